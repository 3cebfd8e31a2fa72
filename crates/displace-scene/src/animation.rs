//! `[animation]`: a scene that changes over frames, so that a farm renders
//! one frame per task. A camera path of keyframes (position and look-at)
//! and optionally a path for one light (a point light's position or an
//! area light's origin), each interpolated linearly or by Catmull-Rom
//! between keys. Frame `F` of a scene is the static scene with the camera
//! and the light moved to where the paths put them at `F`: [`at_frame`]
//! rewrites the parsed scene, and everything after it (checks, bakes,
//! render) is that of any static scene. A path passes through its keys
//! exactly: at a key's frame the key's own numbers are used.

use super::spec::{AnimationSpec, LightSpec, PathKeySpec, SceneSpec, V3};
use crate::error::{Error, Result};
use std::path::Path;

/// Most frames of one animation (`animation.frames`).
pub const MAX_FRAMES: i64 = 1 << 20;

/// How a path moves between its keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Straight lines, constant speed between two keys.
    Linear,
    /// Catmull-Rom through the keys (tangents from the neighbouring keys,
    /// scaled for unevenly spaced frames; the end keys' from their one
    /// neighbour), smooth at every key.
    CatmullRom,
}

/// A path: keyframes `(frame, point)` in increasing frame order.
#[derive(Clone, Debug)]
pub struct Path3 {
    keys: Vec<(f32, [f32; 3])>,
    interpolation: Interpolation,
}

impl Path3 {
    /// The point at `frame`: a key's own point at its frame, the end keys'
    /// before the first and after the last.
    pub fn at(&self, frame: u32) -> [f32; 3] {
        let f = frame as f32;
        let k = &self.keys;
        if let Some((_, p)) = k.iter().find(|(kf, _)| *kf == f) {
            return *p;
        }
        let Some(i) = k.windows(2).position(|w| w[0].0 < f && f < w[1].0) else {
            return if f < k[0].0 { k[0].1 } else { k[k.len() - 1].1 };
        };
        let ((f0, p0), (f1, p1)) = (k[i], k[i + 1]);
        let t = (f - f0) / (f1 - f0);
        match self.interpolation {
            Interpolation::Linear => std::array::from_fn(|c| p0[c] + (p1[c] - p0[c]) * t),
            Interpolation::CatmullRom => {
                // Tangents in units per segment (frames f0..f1).
                let tangent = |j: usize| -> [f32; 3] {
                    let (a, b) = (j.saturating_sub(1), (j + 1).min(k.len() - 1));
                    let scale = (f1 - f0) / (k[b].0 - k[a].0);
                    std::array::from_fn(|c| (k[b].1[c] - k[a].1[c]) * scale)
                };
                let (m0, m1) = (tangent(i), tangent(i + 1));
                let (t2, t3) = (t * t, t * t * t);
                let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
                let h10 = t3 - 2.0 * t2 + t;
                let h01 = -2.0 * t3 + 3.0 * t2;
                let h11 = t3 - t2;
                std::array::from_fn(|c| h00 * p0[c] + h10 * m0[c] + h01 * p1[c] + h11 * m1[c])
            }
        }
    }
}

/// A validated `[animation]`.
#[derive(Clone, Debug)]
pub struct Animation {
    /// Number of frames.
    pub frames: u32,
    /// Frames per second, for the video encoder.
    pub fps: f32,
    /// The camera position's path, if it moves.
    pub camera_position: Option<Path3>,
    /// The look-at point's path, if it moves.
    pub camera_look_at: Option<Path3>,
    /// The light moved (index into `[[lights]]`) and its path.
    pub light: Option<(usize, Path3)>,
}

fn err(name: &Path, message: String) -> Error {
    Error::Scene {
        path: name.to_path_buf(),
        at: None,
        message,
    }
}

/// The keys of one path, checked: frames increasing within the animation,
/// every number finite.
fn path(
    name: &Path,
    keys: impl Iterator<Item = (i64, V3)>,
    frames: u32,
    interpolation: Interpolation,
    what: &str,
) -> Result<Option<Path3>> {
    let mut out: Vec<(f32, [f32; 3])> = Vec::new();
    for (k, (frame, p)) in keys.enumerate() {
        if !(0..i64::from(frames)).contains(&frame) {
            return Err(err(
                name,
                format!("{what}[{k}].frame = {frame}: must be 0..{frames} (animation.frames)"),
            ));
        }
        if let Some((last, _)) = out.last() {
            if frame as f32 <= *last {
                return Err(err(
                    name,
                    format!("{what}[{k}].frame = {frame}: keys must be in increasing frame order (the one before is at {last})"),
                ));
            }
        }
        if !p
            .iter()
            .all(|c| c.is_finite() && c.abs() <= super::MAX_COORDINATE)
        {
            return Err(err(
                name,
                format!(
                    "{what}[{k}] = {p:?}: every component must be a finite number of magnitude at most {:e}",
                    super::MAX_COORDINATE
                ),
            ));
        }
        out.push((frame as f32, p));
    }
    Ok((!out.is_empty()).then_some(Path3 {
        keys: out,
        interpolation,
    }))
}

impl Animation {
    /// Checks `[animation]` against the scene's lights.
    pub fn new(a: &AnimationSpec, lights: usize, name: &Path) -> Result<Self> {
        if !(1..=MAX_FRAMES).contains(&a.frames) {
            return Err(err(
                name,
                format!(
                    "animation.frames must be 1..={MAX_FRAMES}, got {}",
                    a.frames
                ),
            ));
        }
        let frames = a.frames as u32;
        if !(a.fps.is_finite() && a.fps > 0.0) {
            return Err(err(
                name,
                format!("animation.fps must be a positive number, got {}", a.fps),
            ));
        }
        let interpolation = match a.interpolation.as_str() {
            "linear" => Interpolation::Linear,
            "catmull-rom" => Interpolation::CatmullRom,
            other => {
                return Err(err(
                    name,
                    format!(
                    "animation.interpolation = \"{other}\": expected \"linear\" or \"catmull-rom\""
                ),
                ))
            }
        };
        if let Some((k, key)) = a
            .camera
            .iter()
            .enumerate()
            .find(|(_, key)| key.position.is_none() && key.look_at.is_none())
        {
            return Err(err(
                name,
                format!(
                    "animation.camera[{k}] (frame {}) sets neither position nor look_at",
                    key.frame
                ),
            ));
        }
        let keys = |f: fn(&super::spec::CameraKeySpec) -> Option<V3>| {
            a.camera
                .iter()
                .filter_map(move |k| f(k).map(|p| (k.frame, p)))
        };
        let camera_path = |f: fn(&super::spec::CameraKeySpec) -> Option<V3>, what: &str| {
            path(name, keys(f), frames, interpolation, what)
        };
        let camera_position = camera_path(|k| k.position, "animation.camera (position)")?;
        let camera_look_at = camera_path(|k| k.look_at, "animation.camera (look_at)")?;
        let light_path = path(
            name,
            a.light_path
                .iter()
                .map(|k: &PathKeySpec| (k.frame, k.position)),
            frames,
            interpolation,
            "animation.light_path",
        )?;
        // The light index must name a light whenever it is given (the
        // default, 0, names the first where there is a path to move it
        // along): an index past the lights is a mistake with or without a
        // path.
        let index = usize::try_from(a.light).ok().filter(|&i| i < lights);
        if index.is_none() && (light_path.is_some() || a.light != 0) {
            return Err(err(
                name,
                format!(
                    "animation.light = {}: the scene has {lights} [[lights]] (counted from 0)",
                    a.light
                ),
            ));
        }
        let light = light_path.zip(index).map(|(p, i)| (i, p));
        Ok(Self {
            frames,
            fps: a.fps,
            camera_position,
            camera_look_at,
            light,
        })
    }
}

/// Where the camera stands and looks at `frame`: the animated paths, else
/// the scene's `[camera]`.
fn camera_at(spec: &SceneSpec, anim: &Animation, frame: u32) -> (V3, V3) {
    (
        anim.camera_position
            .as_ref()
            .map_or(spec.camera.position, |p| p.at(frame)),
        anim.camera_look_at
            .as_ref()
            .map_or(spec.camera.look_at, |p| p.at(frame)),
    )
}

/// Refuses a frame whose camera the paths put on the point it looks at
/// (the camera would look nowhere), naming the frame: checked for every
/// frame before `--frames` renders any, so a bad key half way through an
/// animation fails before the first frame is written rather than after.
fn check_cameras(
    spec: &SceneSpec,
    anim: &Animation,
    frames: std::ops::Range<u32>,
    name: &Path,
) -> Result<()> {
    for f in frames {
        let (position, look_at) = camera_at(spec, anim, f);
        if position == look_at {
            return Err(err(
                name,
                format!(
                    "animation frame {f}: the camera's position and look_at are both {position:?} (from animation.camera's keys and [camera]): the camera looks nowhere"
                ),
            ));
        }
    }
    Ok(())
}

/// The scene at `frame`: the camera and the animated light moved where
/// the paths put them. A frame for a scene without `[animation]`, or past
/// its last frame, is refused; an animated scene without a frame is frame 0.
pub fn at_frame(mut spec: SceneSpec, frame: Option<u32>, name: &Path) -> Result<SceneSpec> {
    let Some(a) = &spec.animation else {
        return match frame {
            Some(f) => Err(err(
                name,
                format!("--frame {f}: the scene has no [animation]"),
            )),
            None => Ok(spec),
        };
    };
    let anim = Animation::new(a, spec.lights.len(), name)?;
    let f = frame.unwrap_or(0);
    if f >= anim.frames {
        return Err(err(
            name,
            format!(
                "--frame {f}: the animation has {} frames (0..{})",
                anim.frames, anim.frames
            ),
        ));
    }
    check_cameras(&spec, &anim, f..f + 1, name)?;
    (spec.camera.position, spec.camera.look_at) = camera_at(&spec, &anim, f);
    if let Some((i, p)) = &anim.light {
        match &mut spec.lights[*i] {
            LightSpec::Point { position, .. } => *position = p.at(f),
            LightSpec::Area { origin, .. } => *origin = p.at(f),
        }
    }
    Ok(spec)
}

/// The frame count of the parsed scene's animation, if it has one, checked
/// (`--frames` is held to it before any frame is rendered).
pub fn frame_count(spec: &SceneSpec, name: &Path) -> Result<Option<u32>> {
    let Some(a) = &spec.animation else {
        return Ok(None);
    };
    let anim = Animation::new(a, spec.lights.len(), name)?;
    check_cameras(spec, &anim, 0..anim.frames, name)?;
    Ok(Some(anim.frames))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path3(interpolation: Interpolation) -> Path3 {
        Path3 {
            keys: vec![
                (0.0, [0.1, 0.2, 0.3]),
                (3.0, [1.7, -0.3, 2.9]),
                (4.0, [2.0, 5.0, -1.0]),
                (10.0, [0.333, 0.777, 1e-3]),
            ],
            interpolation,
        }
    }

    #[test]
    fn paths_hit_their_keys_exactly() {
        for i in [Interpolation::Linear, Interpolation::CatmullRom] {
            let p = path3(i);
            for (f, k) in &p.keys {
                assert_eq!(p.at(*f as u32), *k, "{i:?} at {f}");
            }
            // Past the ends: the end keys.
            assert_eq!(p.at(11), p.keys[3].1);
        }
    }

    #[test]
    fn between_keys_linear_is_straight_and_catmull_rom_is_smooth() {
        // Frame 1 is a third of the way from key 0 (frame 0) to key 1 (frame 3).
        let lin = path3(Interpolation::Linear);
        let (p0, p1) = ([0.1f32, 0.2, 0.3], [1.7f32, -0.3, 2.9]);
        let a = lin.at(1);
        for c in 0..3 {
            let want = p0[c] + (p1[c] - p0[c]) / 3.0;
            assert!((a[c] - want).abs() < 1e-6, "{a:?}");
        }
        // Catmull-Rom leaves the straight line between keys that turn.
        let curved = path3(Interpolation::CatmullRom).at(1);
        assert!(
            (0..3).any(|c| (curved[c] - a[c]).abs() > 1e-3),
            "{curved:?}"
        );
        // Catmull-Rom on evenly spaced collinear keys is the straight line.
        let cr = Path3 {
            keys: (0..5)
                .map(|k| (2.0 * k as f32, [k as f32, 2.0 * k as f32, 0.0]))
                .collect(),
            interpolation: Interpolation::CatmullRom,
        };
        for f in 2..7 {
            let p = cr.at(f);
            assert!(
                (p[0] - f as f32 / 2.0).abs() < 1e-5 && (p[1] - f as f32).abs() < 1e-5,
                "{f}: {p:?}"
            );
        }
    }
}
