//! The `?key=value&key=value` part of a generator spec. Every generator
//! declares the keys it accepts, so a typo is an error that lists them
//! rather than a parameter silently ignored.

use crate::{Error, Result};

/// Validated parameters of one generator.
pub(super) struct Params {
    generator: &'static str,
    accepted: &'static [&'static str],
    /// Accepted key and its percent-decoded value.
    values: Vec<(&'static str, String)>,
}

impl Params {
    /// Splits `query` (the text after `?`, if any) into pairs, refusing keys
    /// not in `accepted`, repeated keys and malformed pairs. Values are
    /// URL-decoded (`%20` is a space); `+` is kept as a plus sign because
    /// `text` may want one.
    pub fn parse(
        generator: &'static str,
        query: Option<&str>,
        accepted: &'static [&'static str],
    ) -> Result<Self> {
        let mut params = Self {
            generator,
            accepted,
            values: Vec::new(),
        };
        for pair in query.unwrap_or("").split('&').filter(|p| !p.is_empty()) {
            let Some((key, raw)) = pair.split_once('=') else {
                return Err(params.error(pair, format!("`{pair}` is not of the form key=value")));
            };
            let Some(&known) = accepted.iter().find(|k| **k == key) else {
                return Err(params.error(key, "unknown parameter".to_string()));
            };
            if params.raw(known).is_some() {
                return Err(params.error(key, "given more than once".to_string()));
            }
            let value = percent_decode(raw).map_err(|m| params.error(key, m))?;
            params.values.push((known, value));
        }
        Ok(params)
    }

    /// An error about `key`, naming the keys this generator accepts.
    pub fn error(&self, key: &str, message: String) -> Error {
        Error::GeneratorParameter {
            generator: self.generator.to_string(),
            message: format!(
                "parameter `{key}`: {message} (accepted parameters: {})",
                self.accepted.join(", ")
            ),
        }
    }

    fn raw(&self, key: &str) -> Option<&str> {
        self.values
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v.as_str())
    }

    /// A finite number in `[min, max]`, if given.
    pub fn opt_number(&self, key: &str, min: f64, max: f64) -> Result<Option<f64>> {
        let Some(raw) = self.raw(key) else {
            return Ok(None);
        };
        match raw.trim().parse::<f64>() {
            Ok(x) if x.is_finite() && (min..=max).contains(&x) => Ok(Some(x)),
            _ => Err(self.error(key, format!("`{raw}` is not a number in [{min}, {max}]"))),
        }
    }

    pub fn number(&self, key: &str, default: f64, min: f64, max: f64) -> Result<f64> {
        Ok(self.opt_number(key, min, max)?.unwrap_or(default))
    }

    /// A whole number in `[min, max]`, if given.
    pub fn opt_whole(&self, key: &str, min: u64, max: u64) -> Result<Option<u64>> {
        let Some(raw) = self.raw(key) else {
            return Ok(None);
        };
        match raw.trim().parse::<u64>() {
            Ok(x) if (min..=max).contains(&x) => Ok(Some(x)),
            _ => Err(self.error(
                key,
                format!("`{raw}` is not a whole number in [{min}, {max}]"),
            )),
        }
    }

    pub fn whole(&self, key: &str, default: u64, min: u64, max: u64) -> Result<u64> {
        Ok(self.opt_whole(key, min, max)?.unwrap_or(default))
    }

    pub fn flag(&self, key: &str, default: bool) -> Result<bool> {
        match self.raw(key).map(str::trim) {
            None => Ok(default),
            Some("true" | "1" | "yes") => Ok(true),
            Some("false" | "0" | "no") => Ok(false),
            Some(raw) => Err(self.error(key, format!("`{raw}` is not true or false"))),
        }
    }

    pub fn text(&self, key: &str) -> Option<&str> {
        self.raw(key)
    }
}

/// Decodes `%XX` escapes into UTF-8 text.
fn percent_decode(raw: &str) -> std::result::Result<String, String> {
    let bytes = raw.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut k = 0;
    while k < bytes.len() {
        if bytes[k] == b'%' {
            let hex = bytes
                .get(k + 1..k + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("`{raw}` has a `%` not followed by two hex digits"))?;
            out.push(hex);
            k += 3;
        } else {
            out.push(bytes[k]);
            k += 1;
        }
    }
    String::from_utf8(out).map_err(|_| format!("`{raw}` does not decode to UTF-8 text"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const KEYS: &[&str] = &["a", "b"];

    fn message(e: Error) -> String {
        match e {
            Error::GeneratorParameter { message, .. } => message,
            other => panic!("wrong error {other:?}"),
        }
    }

    #[test]
    fn decodes_and_types_values() {
        let p = Params::parse("t", Some("a=1.5&b=Hello%20W%C3%B6rld+"), KEYS).unwrap();
        assert_eq!(p.number("a", 0.0, 0.0, 2.0).unwrap(), 1.5);
        assert_eq!(p.text("b"), Some("Hello Wörld+"));
        let p = Params::parse("t", None, KEYS).unwrap();
        assert_eq!(p.whole("a", 7, 1, 9).unwrap(), 7);
        assert!(p.flag("b", true).unwrap());
        // A trailing `&` is harmless.
        assert!(Params::parse("t", Some("a=1&"), KEYS).is_ok());
    }

    #[test]
    fn refuses_bad_pairs_naming_key_and_accepted_keys() {
        let m = message(Params::parse("t", Some("c=1"), KEYS).err().unwrap());
        assert!(m.contains("`c`") && m.contains("a, b"), "{m}");
        let m = message(Params::parse("t", Some("a"), KEYS).err().unwrap());
        assert!(m.contains("key=value"), "{m}");
        let m = message(Params::parse("t", Some("a=1&a=2"), KEYS).err().unwrap());
        assert!(m.contains("more than once"), "{m}");
        let m = message(Params::parse("t", Some("b=%G1"), KEYS).err().unwrap());
        assert!(m.contains("hex"), "{m}");
        let m = message(Params::parse("t", Some("b=%FF"), KEYS).err().unwrap());
        assert!(m.contains("UTF-8"), "{m}");
        let p = Params::parse("t", Some("a=3&b=maybe"), KEYS).unwrap();
        let m = message(p.number("a", 0.0, 0.0, 2.0).unwrap_err());
        assert!(
            m.contains("`a`") && m.contains("[0, 2]") && m.contains("a, b"),
            "{m}"
        );
        assert!(p.whole("a", 0, 0, 2).is_err());
        assert!(p.flag("b", false).is_err());
        let p = Params::parse("t", Some("a=NaN&b=1.5"), KEYS).unwrap();
        assert!(p.number("a", 0.0, -1e9, 1e9).is_err());
        assert!(p.whole("b", 0, 0, 9).is_err());
    }
}
