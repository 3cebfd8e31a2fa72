"""The README's Python example runs as written (from the repository's
root, where its scene path points) and says what it claims."""

import contextlib
import io
import os
import re

import numpy as np

from conftest import REPO


def test_the_readme_example_runs():
    text = (REPO / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 1, "one Python example in the README"
    env = {}
    cwd = os.getcwd()
    os.chdir(REPO)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(blocks[0], "README.md", "exec"), env)
    finally:
        os.chdir(cwd)
    face, hits, image = env["face"], env["hits"], env["image"]
    assert face.nbytes < 40e6
    # The first ray comes down on the hill, the second runs level 50 m up
    # from the low corner into its flank.
    assert np.all(np.isfinite(hits["t"]))
    assert hits["position"][1, 2] == np.float32(50.0)
    assert image.shape == (240, 320, 3) and np.isfinite(image).all()
