//! Where a scene key's value is in its file: the line and column a value
//! error points at, as a parse error does.
//!
//! Why here and not in every check: the checks work on the parsed
//! description (pbrt-v4's way: each type built from its own parameters),
//! which no longer knows where its values were written; they name the key
//! at fault first in their message (`shapes[2].displacement.depth must be
//! ...`), and [`located`] finds that key once in the file's TOML, spans
//! and all, when an error leaves the build.

use crate::error::{line_column, Error};
use toml::de::{DeTable, DeValue};

/// `e` with the place of the key its message starts with, when it is a
/// scene error without one and the key is in `text`. Anything else is
/// returned as it is.
pub(crate) fn located(e: Error, text: &str) -> Error {
    match e {
        Error::Scene {
            path,
            at: None,
            message,
        } => {
            let at = key_location(text, leading_key(&message));
            Error::Scene { path, at, message }
        }
        other => other,
    }
}

/// The key path a message starts with: its first run of key characters
/// (letters, digits, `_`, `-`, `.`, `[`, `]`), without a trailing `.`.
fn leading_key(message: &str) -> &str {
    let end = message
        .find(|c: char| !(c.is_ascii_alphanumeric() || "_-.[]".contains(c)))
        .unwrap_or(message.len());
    message[..end].trim_end_matches('.')
}

/// Line and column (from 1) of the value of `key` (`image.width`,
/// `materials.wood.color`, `shapes[2].displacement.depth`) in the TOML
/// `text`; where only a leading part of the path is in the file (a key
/// left to its default), the place of the deepest part that is. `None`
/// when not even the first part is, or the text is not TOML.
pub(crate) fn key_location(text: &str, key: &str) -> Option<(usize, usize)> {
    let root = DeValue::Table(DeTable::parse(text).ok()?.into_inner());
    let mut value = &root;
    let mut found = None;
    'path: for part in key.split('.') {
        let (name, indices) = split_indices(part)?;
        let Some(mut entry) = value.get(name) else {
            break;
        };
        found = Some(entry.span());
        for i in indices {
            let Some(e) = entry.get_ref().get(i) else {
                break 'path;
            };
            entry = e;
            found = Some(entry.span());
        }
        value = entry.get_ref();
    }
    found.map(|span| line_column(text, span.start))
}

/// `name[1][2]` as `("name", [1, 2])`; `None` when the brackets do not
/// hold whole numbers.
fn split_indices(part: &str) -> Option<(&str, Vec<usize>)> {
    let (name, mut rest) = part.split_once('[').map_or((part, ""), |(n, r)| (n, r));
    let mut indices = Vec::new();
    while !rest.is_empty() {
        let (index, after) = rest.split_once(']')?;
        indices.push(index.parse().ok()?);
        rest = after.strip_prefix('[').unwrap_or(after);
        if !after.is_empty() && !after.starts_with('[') {
            return None;
        }
    }
    Some((name, indices))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "[image]\nwidth = 0\n\n[materials.wood]\ntype = \"lambert\"\n\
                        color = [1, -1, 1]\n\n[[shapes]]\ntype = \"sphere\"\n\n\
                        [[shapes]]\ntype = \"quad\"\n[shapes.displacement]\n  depth = -2\n";

    #[test]
    fn keys_are_found_where_their_values_are_written() {
        assert_eq!(key_location(TEXT, "image.width"), Some((2, 9)));
        assert_eq!(key_location(TEXT, "materials.wood.color"), Some((6, 9)));
        assert_eq!(
            key_location(TEXT, "shapes[1].displacement.depth"),
            Some((14, 11))
        );
        assert_eq!(key_location(TEXT, "shapes[0].type"), Some((9, 8)));
    }

    #[test]
    fn a_default_is_placed_at_the_deepest_key_written() {
        // `radius` is not in the file: its shape is.
        assert_eq!(key_location(TEXT, "shapes[0].radius"), Some((8, 1)));
        assert_eq!(key_location(TEXT, "camera.position"), None);
        assert_eq!(key_location("not = [toml", "not"), None);
    }

    #[test]
    fn messages_lead_with_their_key() {
        assert_eq!(leading_key("image.width must be positive"), "image.width");
        assert_eq!(leading_key("shapes[3]: degenerate"), "shapes[3]");
        assert_eq!(leading_key("materials.m.color = [1]"), "materials.m.color");
        assert_eq!(leading_key("the scene has no lights."), "the");
        assert_eq!(split_indices("shapes[2][1]"), Some(("shapes", vec![2, 1])));
        assert_eq!(split_indices("shapes[x]"), None);
    }

    #[test]
    fn scene_errors_gain_the_place_of_their_key() {
        let unplaced = |message: &str| Error::Scene {
            path: "s.toml".into(),
            at: None,
            message: message.into(),
        };
        let negative = "materials.wood.color = [1.0, -1.0, 1.0]: colours cannot be negative";
        assert_eq!(
            located(unplaced(negative), TEXT).to_string(),
            format!("s.toml:6:9: {negative}")
        );
        assert_eq!(
            located(unplaced("no such key anywhere"), TEXT).to_string(),
            "s.toml: no such key anywhere"
        );
    }
}
