"""Long jobs release the GIL, stop on Ctrl-C with KeyboardInterrupt, and
report progress to a callback on the calling thread."""

import os
import signal
import threading
import time

import numpy as np
import pytest

import displace
from conftest import REPO


def interrupt_after(seconds):
    """Sends this process SIGINT (what Ctrl-C sends) after `seconds`."""
    t = threading.Timer(seconds, lambda: os.kill(os.getpid(), signal.SIGINT))
    t.start()
    return t


@pytest.fixture(autouse=True)
def keyboard_interrupt_handler():
    """Python's own SIGINT handler (KeyboardInterrupt) for these tests.

    Python installs it at start-up only when SIGINT is not ignored, and a
    shell that starts the suite in the background (`bash .ci/run &`, nohup
    under a non-interactive shell) hands it SIGINT ignored: the signal
    would then never reach the binding, and the test would wait out the
    whole render. What is under test is what the binding does with the
    handler an interactive Python has.
    """
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="module")
def scene():
    return displace.Scene(REPO / "scenes" / "cornell_studded.toml", cache=False)


def test_ctrl_c_stops_a_long_render(scene):
    # About a minute of work on two cores: stopped within a second of the signal.
    start = time.monotonic()
    timer = interrupt_after(0.5)
    with pytest.raises(KeyboardInterrupt):
        scene.render(spp=4096, size=(256, 256))
    timer.join()
    assert time.monotonic() - start < 10.0
    # The scene still renders afterwards.
    assert scene.render(spp=1, size=(16, 16)).shape == (16, 16, 3)


def test_ctrl_c_stops_a_long_bake():
    start = time.monotonic()
    timer = interrupt_after(0.3)
    with pytest.raises(KeyboardInterrupt):
        displace.bake("gen:noise", size=(1024, 1024, 128))
    timer.join()
    assert time.monotonic() - start < 10.0


def test_progress_is_reported_and_its_exception_stops_the_job(scene):
    seen = []
    img = scene.render(spp=1, size=(64, 64), progress=lambda done, total: seen.append((done, total)))
    assert img.shape == (64, 64, 3)
    assert seen and seen[-1][0] == seen[-1][1] and all(0 <= d <= t for d, t in seen)

    class Stop(Exception):
        pass

    def stop(done, total):
        raise Stop(f"at {done}/{total}")

    with pytest.raises(Stop):
        scene.render(spp=2048, size=(128, 128), progress=stop)
    bake_seen = []
    displace.bake("gen:studded", size=(64, 64, 32), progress=lambda d, t: bake_seen.append((d, t)))
    assert bake_seen and bake_seen[-1] == (32, 32)


def test_queries_release_the_gil():
    """Another Python thread runs while a query traces."""
    face = displace.bake("gen:noise", size=(256, 256, 16))
    rng = np.random.default_rng(3)
    n = 2_000_000
    o = np.column_stack([rng.uniform(0, 1, n), rng.uniform(0, 1, n), np.full(n, 0.2)]).astype(np.float32)
    d = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.full(n, -0.05)]).astype(np.float32)
    ticks = []
    stop = threading.Event()

    def ticker():
        while not stop.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.005)

    t = threading.Thread(target=ticker)
    t.start()
    start = time.monotonic()
    face.intersect(o, d, threads=1)
    elapsed = time.monotonic() - start
    stop.set()
    t.join()
    during = [x for x in ticks if start < x < start + elapsed]
    assert elapsed > 0.1, "the query must be long enough to tell"
    assert len(during) >= 0.3 * elapsed / 0.005, f"{len(during)} ticks in {elapsed:.2f} s"
