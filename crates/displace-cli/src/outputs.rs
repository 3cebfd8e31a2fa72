//! Checks on a command's outputs, made before any work: the file type and
//! the directory can be written, two outputs do not name one file, and no
//! output names one of the command's inputs.

use anyhow::{bail, Context, Result};
use displace_core::io::MapFile;
use std::path::Path;

/// Refuses an output path whose file type or directory cannot work, before
/// any time is spent baking.
pub fn check_output(path: &Path) -> Result<MapFile> {
    let kind = MapFile::from_path(path).with_context(|| format!("output {}", path.display()))?;
    check_output_dir(path)?;
    Ok(kind)
}

/// Longest file name the file systems in use take (`NAME_MAX`), in bytes.
const NAME_MAX: usize = 255;

/// Refuses an output path whose directory does not exist, or whose file
/// name is longer than a file system takes, so that no work is done for a
/// file that cannot be written.
pub fn check_output_dir(path: &Path) -> Result<()> {
    use std::os::unix::ffi::OsStrExt;
    if let Some(name) = path.file_name() {
        if name.as_bytes().len() > NAME_MAX {
            bail!(
                "output {}: its file name is {} bytes, more than the {NAME_MAX} a file system takes",
                path.display(),
                name.as_bytes().len()
            );
        }
    }
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        if !dir.is_dir() {
            bail!(
                "output {}: directory {} does not exist",
                path.display(),
                dir.display()
            );
        }
    }
    Ok(())
}

/// `trace` writes `.npy` only; checked before any work is done, with a
/// message that names only what trace can write.
pub fn check_npy_output(path: &Path) -> Result<()> {
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"))
    {
        bail!("output {}: hits are written as .npy", path.display());
    }
    check_output_dir(path)
}

/// Refuses two outputs of one command that name the same file: the later
/// write would silently replace the earlier one.
pub fn check_distinct_outputs(outputs: &[(&str, &Path)]) -> Result<()> {
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    for (i, (a_name, a)) in outputs.iter().enumerate() {
        for (b_name, b) in &outputs[..i] {
            if absolute(a) == absolute(b) {
                bail!(
                    "{b_name} and {a_name} are the same file ({}): each output needs its own path",
                    a.display()
                );
            }
        }
    }
    Ok(())
}

/// Refuses an output that names one of the command's inputs (the same
/// file, through whatever path: a link or `./` counts): the output is
/// written under a temporary name and renamed over the path at the end, so
/// the input would be replaced by what was made from it. Generated inputs
/// (`gen:...`, `builtin:...`) and inputs that do not exist yet name no
/// file.
pub fn check_not_inputs(outputs: &[(&str, &Path)], inputs: &[(&str, &Path)]) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let identity = |p: &Path| std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()));
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    for (out_name, out) in outputs {
        let out_id = identity(out);
        for (in_name, input) in inputs {
            let same = match (out_id, identity(input)) {
                (Some(a), Some(b)) => a == b,
                _ => absolute(out) == absolute(input),
            };
            if same {
                bail!(
                    "{out_name} {} is also an input ({in_name}): writing it would replace the file it is made from; choose another output path",
                    out.display()
                );
            }
        }
    }
    Ok(())
}

/// [`check_not_inputs`] for a command that writes `outputs` (its image and
/// every file named after it: AOVs, a UV image) from a loaded scene: every
/// file the scene read (height maps, textures, meshes), and the scene file
/// itself where given.
pub fn check_not_scene_inputs(
    outputs: &[(String, std::path::PathBuf)],
    sources: &[std::path::PathBuf],
    scene_file: Option<&Path>,
) -> Result<()> {
    let mut read: Vec<(&str, &Path)> = sources
        .iter()
        .map(|p| ("a file the scene reads", p.as_path()))
        .collect();
    read.extend(scene_file.map(|p| ("scene", p)));
    let written: Vec<(&str, &Path)> = outputs
        .iter()
        .map(|(name, p)| (name.as_str(), p.as_path()))
        .collect();
    check_not_inputs(&written, &read)
}
