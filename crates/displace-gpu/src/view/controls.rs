//! What the viewer's keys, mouse and `--script` commands do: one
//! [`Action`] per input, one key table shared by the window, the script's
//! `key NAME` command and the help text.

use crate::{Error, Result, Shadows};
use displace_core::Method;

/// Highest iteration count the `.` key or a script may ask for.
pub const MAX_ITERATIONS: u32 = 4096;

/// One change to the view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Turn the camera about its target: degrees about the up axis, degrees
    /// up towards it.
    Orbit {
        /// Degrees about the up axis.
        yaw: f32,
        /// Degrees up towards it.
        raise: f32,
    },
    /// Multiply the camera's distance to its target.
    Zoom(f32),
    /// Set the depth scale (times the scene's displacement depth).
    Depth(f32),
    /// Multiply the depth scale.
    DepthBy(f32),
    /// Set the sphere-tracing step count.
    Iterations(u32),
    /// Double (`true`) or halve the iteration count.
    IterationsStep(bool),
    /// Set the trace method.
    Method(Method),
    /// Switch between Donnelly's fixed loop and ours.
    ToggleMethod,
    /// Set the self-shadowing mode.
    Shadows(Shadows),
    /// Next self-shadowing mode (none, hard, soft).
    CycleShadows,
    /// Turn the light about the camera's target, as `Orbit` turns the eye.
    Light {
        /// Degrees about the up axis.
        yaw: f32,
        /// Degrees up towards it.
        raise: f32,
    },
    /// Show or hide the overlay.
    Hud(bool),
    /// Flip the overlay.
    ToggleHud,
    /// Back to the scene's own camera, light and settings.
    Reset,
    /// Close the viewer.
    Quit,
    /// Script only: ask the window for this inner size.
    Resize([u32; 2]),
    /// Script only: hold the commands after this one until this many
    /// frames have been presented.
    AfterFrame(u32),
}

/// Degrees per press of an orbit or light key.
const KEY_TURN: f32 = 5.0;
/// Distance factor per zoom key press or wheel notch.
pub const ZOOM_STEP: f32 = 1.1;
const DEPTH_STEP: f32 = 1.25;

/// Key names (as [`key_name`] spells winit's keys) and what they do.
pub const KEYS: &[(&str, Action)] = &[
    (
        "left",
        Action::Orbit {
            yaw: -KEY_TURN,
            raise: 0.0,
        },
    ),
    (
        "right",
        Action::Orbit {
            yaw: KEY_TURN,
            raise: 0.0,
        },
    ),
    (
        "up",
        Action::Orbit {
            yaw: 0.0,
            raise: KEY_TURN,
        },
    ),
    (
        "down",
        Action::Orbit {
            yaw: 0.0,
            raise: -KEY_TURN,
        },
    ),
    ("pageup", Action::Zoom(1.0 / ZOOM_STEP)),
    ("=", Action::Zoom(1.0 / ZOOM_STEP)),
    ("+", Action::Zoom(1.0 / ZOOM_STEP)),
    ("pagedown", Action::Zoom(ZOOM_STEP)),
    ("-", Action::Zoom(ZOOM_STEP)),
    ("]", Action::DepthBy(DEPTH_STEP)),
    ("[", Action::DepthBy(1.0 / DEPTH_STEP)),
    (".", Action::IterationsStep(true)),
    (",", Action::IterationsStep(false)),
    ("m", Action::ToggleMethod),
    ("s", Action::CycleShadows),
    (
        "j",
        Action::Light {
            yaw: -3.0 * KEY_TURN,
            raise: 0.0,
        },
    ),
    (
        "l",
        Action::Light {
            yaw: 3.0 * KEY_TURN,
            raise: 0.0,
        },
    ),
    (
        "i",
        Action::Light {
            yaw: 0.0,
            raise: KEY_TURN,
        },
    ),
    (
        "k",
        Action::Light {
            yaw: 0.0,
            raise: -KEY_TURN,
        },
    ),
    ("h", Action::ToggleHud),
    ("r", Action::Reset),
    ("escape", Action::Quit),
    ("q", Action::Quit),
];

/// The keys as `displace view --help` lists them (checked against
/// [`KEYS`] by a test).
pub const KEYS_HELP: &str = "\
Mouse: drag with the left button to orbit, wheel to zoom.
Keys:
  left right up down  orbit the camera (5 degrees a press)
  pageup = +          zoom in          pagedown -   zoom out
  ] [                 depth scale x1.25 / /1.25 (listing 8-1's inverse bump
                      depth factor: no re-bake)
  . ,                 double / halve the iteration count
  m                   method: sphere (early out) <-> sphere-fixed (Donnelly's)
  s                   shadows: none -> hard -> soft
  j l i k             light: turn left / right, raise / lower
  h                   overlay on/off (the title bar always shows it)
  r                   reset camera, light and settings
  escape q            quit
Script (--script, `;`-separated, applied before the first frame unless
after a `frame N`, which holds the rest until N frames were shown):
  orbit YAW RAISE | zoom F | depth SCALE | iterations N |
  method sphere|sphere-fixed|early-out|fixed | shadows none|hard|soft |
  light YAW RAISE | hud on|off | key NAME | reset | size WxH | frame N";

/// The [`KEYS`] name of a winit key, lower case.
pub fn key_name(key: &winit::keyboard::Key) -> Option<String> {
    use winit::keyboard::{Key, NamedKey};
    match key {
        Key::Named(named) => Some(
            match named {
                NamedKey::ArrowLeft => "left",
                NamedKey::ArrowRight => "right",
                NamedKey::ArrowUp => "up",
                NamedKey::ArrowDown => "down",
                NamedKey::PageUp => "pageup",
                NamedKey::PageDown => "pagedown",
                NamedKey::Escape => "escape",
                _ => return None,
            }
            .to_string(),
        ),
        Key::Character(c) => Some(c.to_lowercase()),
        _ => None,
    }
}

/// What key `name` does, if anything.
pub fn key_action(name: &str) -> Option<Action> {
    let name = name.to_lowercase();
    KEYS.iter().find(|(k, _)| *k == name).map(|(_, a)| *a)
}

/// Parses a `--script`: commands separated by `;` (see [`KEYS_HELP`]).
pub fn parse_script(script: &str) -> Result<Vec<Action>> {
    script
        .split(';')
        .map(str::trim)
        .filter(|c| !c.is_empty())
        .enumerate()
        .map(|(k, cmd)| {
            parse_command(cmd).map_err(|why| {
                Error::InvalidOption(format!("--script command {} `{cmd}`: {why}", k + 1))
            })
        })
        .collect()
}

fn parse_command(cmd: &str) -> std::result::Result<Action, String> {
    let words: Vec<&str> = cmd.split_whitespace().collect();
    let args = &words[1..];
    let want = |n: usize| {
        if args.len() == n {
            Ok(())
        } else {
            Err(format!("expected {n} argument(s), got {}", args.len()))
        }
    };
    let number = |s: &str| -> std::result::Result<f32, String> {
        s.parse::<f32>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("`{s}` is not a finite number"))
    };
    match words[0] {
        "orbit" | "light" => {
            want(2)?;
            let (yaw, raise) = (number(args[0])?, number(args[1])?);
            Ok(if words[0] == "orbit" {
                Action::Orbit { yaw, raise }
            } else {
                Action::Light { yaw, raise }
            })
        }
        "zoom" | "depth" => {
            want(1)?;
            let v = number(args[0])?;
            if v <= 0.0 {
                return Err(format!("`{v}` must be positive"));
            }
            Ok(if words[0] == "zoom" {
                Action::Zoom(v)
            } else {
                Action::Depth(v)
            })
        }
        "iterations" => {
            want(1)?;
            match args[0].parse::<u32>() {
                Ok(n) if (1..=MAX_ITERATIONS).contains(&n) => Ok(Action::Iterations(n)),
                _ => Err(format!("`{}` is not in 1..={MAX_ITERATIONS}", args[0])),
            }
        }
        "method" => {
            want(1)?;
            match args[0] {
                "sphere" | "early-out" => Ok(Action::Method(Method::Sphere)),
                "sphere-fixed" | "fixed" => Ok(Action::Method(Method::SphereFixed)),
                o => Err(format!(
                    "unknown method `{o}` (expected sphere, sphere-fixed, early-out or fixed)"
                )),
            }
        }
        "shadows" => {
            want(1)?;
            args[0]
                .parse()
                .map(Action::Shadows)
                .map_err(|e: Error| e.to_string())
        }
        "hud" => {
            want(1)?;
            match args[0] {
                "on" => Ok(Action::Hud(true)),
                "off" => Ok(Action::Hud(false)),
                o => Err(format!("`{o}` (expected on or off)")),
            }
        }
        "key" => {
            want(1)?;
            key_action(args[0]).ok_or_else(|| format!("no key `{}` (see --help)", args[0]))
        }
        "reset" => want(0).map(|_| Action::Reset),
        "size" => {
            want(1)?;
            let [w, h] =
                displace_core::convention::parse_size::<2>(args[0]).map_err(|e| e.to_string())?;
            let max = crate::raster::MAX_IMAGE_EDGE as usize;
            if w > max || h > max {
                return Err(format!("each side must be at most {max}"));
            }
            Ok(Action::Resize([w as u32, h as u32]))
        }
        "frame" => {
            want(1)?;
            args[0]
                .parse::<u32>()
                .map(Action::AfterFrame)
                .map_err(|_| format!("`{}` is not a frame count", args[0]))
        }
        o => Err(format!("unknown command `{o}` (see --help)")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_is_in_the_help() {
        for (name, _) in KEYS {
            assert!(
                KEYS_HELP.split_whitespace().any(|w| w == *name),
                "key `{name}` missing from KEYS_HELP"
            );
        }
    }

    #[test]
    fn scripts_parse_into_actions() {
        let a = parse_script(
            "orbit 30 -10; depth 0.5 ;method fixed; shadows soft; iterations 8; key m; light 90 0; hud off; zoom 2; reset; frame 3; size 20x10",
        )
        .unwrap();
        assert_eq!(
            a,
            vec![
                Action::Orbit {
                    yaw: 30.0,
                    raise: -10.0
                },
                Action::Depth(0.5),
                Action::Method(Method::SphereFixed),
                Action::Shadows(Shadows::Soft),
                Action::Iterations(8),
                Action::ToggleMethod,
                Action::Light {
                    yaw: 90.0,
                    raise: 0.0
                },
                Action::Hud(false),
                Action::Zoom(2.0),
                Action::Reset,
                Action::AfterFrame(3),
                Action::Resize([20, 10]),
            ]
        );
    }

    #[test]
    fn bad_scripts_name_the_command() {
        for (script, needle) in [
            ("orbit 1", "command 1 `orbit 1`: expected 2"),
            (
                "depth 1; depth -1",
                "command 2 `depth -1`: `-1` must be positive",
            ),
            ("iterations 0", "not in 1..=4096"),
            ("method exact", "unknown method `exact`"),
            ("shadows dim", "unknown shadows `dim`"),
            ("key f13", "no key `f13`"),
            ("fly 1", "unknown command `fly`"),
            ("zoom nan", "not a finite number"),
            ("size 0x4", "size 0x4"),
            ("size 99999x4", "at most 16384"),
            ("frame -1", "not a frame count"),
        ] {
            let e = parse_script(script).unwrap_err().to_string();
            assert!(e.contains(needle), "{script}: {e}");
        }
    }
}
