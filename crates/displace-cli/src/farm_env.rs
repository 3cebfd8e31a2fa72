//! The task index a scheduler gives each task of an array (`--tile auto/N`,
//! `--frame auto`): Slurm's `SLURM_ARRAY_TASK_ID` or Kubernetes' Indexed
//! Job `JOB_COMPLETION_INDEX`. Neither set is refused rather than guessed
//! (every task would render tile 0), and both set to different values too.

use anyhow::{bail, Result};

/// The variables read, in order, with what sets them (for messages).
pub const VARIABLES: [(&str, &str); 2] = [
    ("SLURM_ARRAY_TASK_ID", "a Slurm array job"),
    ("JOB_COMPLETION_INDEX", "a Kubernetes Indexed Job"),
];

/// The task index from the process environment; `flag` is the option
/// being resolved, named in errors.
pub fn task_index(flag: &str) -> Result<u32> {
    task_index_from(flag, |name| std::env::var(name).ok())
}

/// [`task_index`] over any lookup (tests pass a map).
pub fn task_index_from(flag: &str, var: impl Fn(&str) -> Option<String>) -> Result<u32> {
    let mut found: Option<(&str, u32)> = None;
    for (name, _) in VARIABLES {
        let Some(value) = var(name).filter(|v| !v.trim().is_empty()) else {
            continue;
        };
        let Ok(index) = value.trim().parse::<u32>() else {
            bail!("{flag}: {name} = `{value}` is not a task index (a whole number from 0)");
        };
        match found {
            Some((other, i)) if i != index => {
                bail!("{flag}: {other} = {i} and {name} = {index} disagree; set one of them")
            }
            Some(_) => {}
            None => found = Some((name, index)),
        }
    }
    match found {
        Some((_, i)) => Ok(i),
        None => bail!(
            "{flag}: no task index: neither {} ({}) nor {} ({}) is set; give the index itself instead of `auto`",
            VARIABLES[0].0,
            VARIABLES[0].1,
            VARIABLES[1].0,
            VARIABLES[1].1
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |n| {
            vars.iter()
                .find(|(k, _)| *k == n)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn either_variable_gives_the_index_and_none_is_refused() {
        assert_eq!(
            task_index_from("--tile", with(&[("SLURM_ARRAY_TASK_ID", "3")])).unwrap(),
            3
        );
        assert_eq!(
            task_index_from("--tile", with(&[("JOB_COMPLETION_INDEX", "5")])).unwrap(),
            5
        );
        assert_eq!(
            task_index_from(
                "--tile",
                with(&[("SLURM_ARRAY_TASK_ID", "2"), ("JOB_COMPLETION_INDEX", "2")])
            )
            .unwrap(),
            2
        );
        let none = task_index_from("--tile auto/8", with(&[]))
            .unwrap_err()
            .to_string();
        assert!(
            none.contains("SLURM_ARRAY_TASK_ID") && none.contains("JOB_COMPLETION_INDEX"),
            "{none}"
        );
        let both = task_index_from(
            "--tile",
            with(&[("SLURM_ARRAY_TASK_ID", "1"), ("JOB_COMPLETION_INDEX", "2")]),
        )
        .unwrap_err()
        .to_string();
        assert!(both.contains("disagree"), "{both}");
        let junk = task_index_from("--frame", with(&[("SLURM_ARRAY_TASK_ID", "x")]))
            .unwrap_err()
            .to_string();
        assert!(junk.contains("`x`"), "{junk}");
    }
}
