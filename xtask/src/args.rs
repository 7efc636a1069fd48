//! The one flag parser of every xtask subcommand: each names the flags it knows, and an unknown flag, a
//! flag without its value or a stray argument is an error that lists the known flags and the usage.

use std::str::FromStr;

use crate::util::Result;

/// What follows a flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Takes {
    /// Nothing: `--release`.
    Nothing,
    /// A value: `--out DIR`.
    Value,
    /// A number: `--steps N`.
    Number,
}

/// The flags a subcommand knows.
pub type Known = [(&'static str, Takes)];

/// The flags given to a subcommand (in order) and its leading positional arguments.
#[derive(Debug, Default, PartialEq)]
pub struct Flags {
    pub positional: Vec<String>,
    given: Vec<(&'static str, Option<String>)>,
}

fn listing(known: &Known) -> String {
    let shown: Vec<String> = known
        .iter()
        .map(|&(name, takes)| match takes {
            Takes::Nothing => name.to_string(),
            Takes::Value => format!("{name} VALUE"),
            Takes::Number => format!("{name} N"),
        })
        .collect();
    if shown.is_empty() { "none".into() } else { shown.join(", ") }
}

impl Flags {
    /// Parses `args`: up to `positional` leading arguments that are not flags, then only flags of `known`.
    pub fn parse(args: &[String], known: &Known, positional: usize, usage: &str) -> Result<Flags> {
        let fail = |what: String| format!("{what}; the known flags are: {}\nusage: {usage}", listing(known));
        let mut flags = Flags::default();
        let mut it = args.iter().peekable();
        while flags.positional.len() < positional {
            match it.next_if(|a| !a.starts_with("--")) {
                Some(a) => flags.positional.push(a.clone()),
                None => break,
            }
        }
        while let Some(a) = it.next() {
            let Some(&(name, takes)) = known.iter().find(|(name, _)| name == a) else {
                let what = if a.starts_with('-') { "unknown flag" } else { "unexpected argument" };
                return Err(fail(format!("{what} `{a}`")));
            };
            let value = match takes {
                Takes::Nothing => None,
                Takes::Value | Takes::Number => {
                    let need = if takes == Takes::Number { "a number" } else { "a value" };
                    let v = it.next().ok_or_else(|| format!("{name} needs {need}\nusage: {usage}"))?;
                    if takes == Takes::Number && v.parse::<f64>().is_err() {
                        return Err(format!("{name} {v}: {name} needs a number\nusage: {usage}"));
                    }
                    Some(v.clone())
                }
            };
            flags.given.push((name, value));
        }
        Ok(flags)
    }

    /// Whether `name` was given.
    pub fn has(&self, name: &str) -> bool {
        self.given.iter().any(|(n, _)| *n == name)
    }

    /// The value of the last `name` given.
    pub fn value(&self, name: &str) -> Option<&str> {
        self.given.iter().rev().find(|(n, _)| *n == name).and_then(|(_, v)| v.as_deref())
    }

    /// The number after `name`, or `default` where the flag is absent.
    pub fn number<T: FromStr>(&self, name: &str, default: T) -> Result<T> {
        match self.value(name) {
            Some(v) => v.parse().map_err(|_| format!("{name} {v}: {name} needs a number")),
            None => Ok(default),
        }
    }

    /// The flags of the actions in `names` that were given, in order.
    pub fn given_of(&self, names: &[&str]) -> Vec<&'static str> {
        self.given.iter().map(|(n, _)| *n).filter(|n| names.contains(n)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    const KNOWN: &Known = &[("--release", Takes::Nothing), ("--steps", Takes::Number), ("--out", Takes::Value)];

    #[test]
    fn number_arg_reads_the_value_after_its_flag() {
        let known = [("--steps", Takes::Number), ("--size", Takes::Number), ("--spp", Takes::Number)];
        let a = args("bench --steps 12 --spp");
        let f = Flags::parse(&a[..3], &known, 1, "u").unwrap();
        assert_eq!(f.number("--steps", 60u32), Ok(12));
        assert_eq!(f.number("--size", 128u32), Ok(128));
        let err = Flags::parse(&a, &known, 1, "u").unwrap_err();
        assert!(err.starts_with("--spp needs a number"), "{err}");
        let err = Flags::parse(&args("--steps many"), KNOWN, 0, "u").unwrap_err();
        assert!(err.contains("--steps needs a number"), "{err}");
        let f = Flags::parse(&args("--release --out a --out b"), KNOWN, 0, "u").unwrap();
        assert!(f.has("--release") && !f.has("--steps"));
        assert_eq!(f.value("--out"), Some("b"), "the last one wins");
    }

    /// A mistyped flag is an error naming it and the flags that exist, never ignored.
    #[test]
    fn an_unknown_flag_lists_the_known_ones() {
        let err = Flags::parse(&args("--stpes 3"), KNOWN, 0, "cargo xtask x").unwrap_err();
        assert!(err.contains("unknown flag `--stpes`"), "{err}");
        assert!(err.contains("--release, --steps N, --out VALUE") && err.contains("usage: cargo xtask x"), "{err}");
        let err = Flags::parse(&args("extra"), KNOWN, 0, "u").unwrap_err();
        assert!(err.contains("unexpected argument `extra`"), "{err}");
        let f = Flags::parse(&args("loss --release"), KNOWN, 1, "u").unwrap();
        assert_eq!(f.positional, ["loss"]);
        assert!(Flags::parse(&args("loss more"), KNOWN, 1, "u").unwrap_err().contains("`more`"));
        assert!(Flags::parse(&args("--release"), &[], 0, "u").unwrap_err().contains("known flags are: none"));
    }
}
