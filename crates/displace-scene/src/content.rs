//! The content hash of a render: what a tile file carries so that `merge`
//! can tell tiles of one render from tiles of another. It covers the scene
//! text, the bytes of every file the scene reads (height maps, textures,
//! meshes; by content, not by path, so that machines mounting the shared
//! file system at different places agree), and the command-line overrides
//! (`--spp`, `--size`, `--method`, `--integrator`, `--sampler`, `--frame`). The seed is part of the scene text. Where the bake cache lives does not
//! change the image, so it is left out.

use super::SceneOptions;
use crate::error::Result;
use crate::sampler::hash_iter;
use std::path::PathBuf;

/// Bumped when the same inputs could render differently (a change of the
/// hash's own layout counts too).
const CONTENT_VERSION: u64 = 2;

/// The hash of `bytes` and their length, as 64-bit words.
fn bytes_hash(bytes: &[u8]) -> u64 {
    hash_iter(
        std::iter::once(bytes.len() as u64).chain(bytes.chunks(8).map(|c| {
            let mut w = [0u8; 8];
            w[..c.len()].copy_from_slice(c);
            u64::from_le_bytes(w)
        })),
    )
}

/// The content hash of a scene given as `text`, reading `sources` and
/// folding in `opts`' overrides.
pub(crate) fn content_hash(text: &str, sources: &[PathBuf], opts: &SceneOptions) -> Result<u64> {
    let mut files = Vec::with_capacity(sources.len());
    for path in sources {
        let bytes = std::fs::read(path).map_err(|e| displace_core::Error::io(path, e))?;
        files.push(bytes_hash(&bytes));
    }
    // The order a scene lists its files in is already in its text.
    files.sort_unstable();
    let option = |v: Option<u64>| [v.is_some() as u64, v.unwrap_or(0)];
    let mut words = vec![CONTENT_VERSION, bytes_hash(text.as_bytes())];
    words.push(files.len() as u64);
    words.extend(files);
    words.extend(option(opts.spp.map(u64::from)));
    words.extend(option(
        opts.size.map(|[w, h]| (u64::from(w) << 32) | u64::from(h)),
    ));
    words.extend(option(
        opts.method.map(|m| bytes_hash(format!("{m:?}").as_bytes())),
    ));
    words.extend(option(opts.frame.map(u64::from)));
    words.extend(option(
        opts.integrator
            .map(|i| bytes_hash(format!("{i:?}").as_bytes())),
    ));
    words.extend(option(
        opts.sampler.map(|k| bytes_hash(k.name().as_bytes())),
    ));
    Ok(hash_iter(words))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_input_changes_the_hash() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("h.png");
        std::fs::write(&file, b"one").unwrap();
        let base = SceneOptions::default();
        let h = |text: &str, o: &SceneOptions| {
            content_hash(text, std::slice::from_ref(&file), o).unwrap()
        };
        let a = h("seed = 1", &base);
        assert_eq!(a, h("seed = 1", &base), "not deterministic");
        assert_ne!(a, h("seed = 2", &base));
        for o in [
            SceneOptions {
                spp: Some(4),
                ..SceneOptions::default()
            },
            SceneOptions {
                size: Some([8, 8]),
                ..SceneOptions::default()
            },
            SceneOptions {
                method: Some(displace_core::Method::Exact),
                ..SceneOptions::default()
            },
            SceneOptions {
                frame: Some(0),
                ..SceneOptions::default()
            },
            SceneOptions {
                integrator: Some(crate::settings::Integrator::Path),
                ..SceneOptions::default()
            },
            SceneOptions {
                sampler: Some(crate::sampler::SamplerKind::Independent),
                ..SceneOptions::default()
            },
        ] {
            assert_ne!(a, h("seed = 1", &o), "{o:?}");
        }
        // The cache's place does not change the image.
        let cached = SceneOptions {
            cache_dir: Some(dir.path().into()),
            ..SceneOptions::default()
        };
        assert_eq!(a, h("seed = 1", &cached));
        std::fs::write(&file, b"two").unwrap();
        assert_ne!(a, h("seed = 1", &base), "a referenced file's bytes");
        // A byte string and its zero-padded extension differ.
        assert_ne!(bytes_hash(b"ab"), bytes_hash(b"ab\0"));
    }
}
