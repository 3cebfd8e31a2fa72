//! Parsing a name into one of a fixed list of values (an addressing mode, a
//! storage format, a shadow mode), with the refusal every option words
//! alike: what was given, and every name that would have done (as a list
//! with "or", or, for the renderer's scene keys, after "known:").

/// The value `choices` pairs with the name `given`, or the message
/// ``unknown {what} `{given}` (expected a, b or c)`` listing every name in
/// order.
pub fn parse_choice<T: Copy>(what: &str, given: &str, choices: &[(&str, T)]) -> Result<T, String> {
    find(given, choices).ok_or_else(|| {
        let names = or_list(choices.iter().map(|(name, _)| *name));
        format!("unknown {what} `{given}` (expected {names})")
    })
}

/// [`parse_choice`] with the refusal ``unknown {what} `{given}` (known: a,
/// b, c)``, as the renderer's scene keys word it.
pub fn parse_known<T: Copy>(what: &str, given: &str, choices: &[(&str, T)]) -> Result<T, String> {
    find(given, choices).ok_or_else(|| {
        let names: Vec<&str> = choices.iter().map(|(name, _)| *name).collect();
        format!("unknown {what} `{given}` (known: {})", names.join(", "))
    })
}

fn find<T: Copy>(given: &str, choices: &[(&str, T)]) -> Option<T> {
    choices
        .iter()
        .find(|(name, _)| *name == given)
        .map(|&(_, value)| value)
}

/// `a`, `a or b`, `a, b or c`: names as the refusals list them.
pub fn or_list<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    let names: Vec<&str> = names.into_iter().collect();
    match names.split_last() {
        None => String::new(),
        Some((last, [])) => last.to_string(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_list_every_name() {
        let choices = [("a", 1), ("b", 2), ("c", 3)];
        assert_eq!(parse_choice("letter", "b", &choices), Ok(2));
        assert_eq!(
            parse_choice("letter", "d", &choices),
            Err("unknown letter `d` (expected a, b or c)".to_string())
        );
        assert_eq!(
            parse_choice("letter", "x", &choices[..2]),
            Err("unknown letter `x` (expected a or b)".to_string())
        );
        assert_eq!(or_list(["only"]), "only");
        assert_eq!(
            parse_known("letter", "d", &choices),
            Err("unknown letter `d` (known: a, b, c)".to_string())
        );
    }
}
