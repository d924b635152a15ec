//! A command line built from typed values, flag by flag, for where halftrace runs itself (each
//! `device-report` step, `isa`'s model processes): the command's own arguments type build it
//! (`commands/<name>.rs`, `isa::ModelArgs`), and a test there parses it back with clap, so a
//! renamed flag fails in the tests, not in a child at run time. Values go as `--flag=value`,
//! so one starting with `-` stays a value.

use std::fmt::Display;

/// A child's arguments, the subcommand first.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Argv(pub Vec<String>);

impl Argv {
    /// Starts the arguments of subcommand `cmd`.
    pub fn new(cmd: &str) -> Argv {
        Argv(vec![cmd.to_string()])
    }
    /// `--name` where `on`.
    pub fn flag(mut self, name: &str, on: bool) -> Argv {
        if on {
            self.0.push(format!("--{name}"));
        }
        self
    }
    /// `--name=value` where there is a value.
    pub fn opt<T: Display>(mut self, name: &str, v: Option<T>) -> Argv {
        if let Some(v) = v {
            self.0.push(format!("--{name}={v}"));
        }
        self
    }
    /// `--name=value` once per value (a repeated flag).
    pub fn each<T: Display>(mut self, name: &str, vs: impl IntoIterator<Item = T>) -> Argv {
        for v in vs {
            self.0.push(format!("--{name}={v}"));
        }
        self
    }
    /// `--name=a,b,c` where there are values (a comma-delimited flag).
    pub fn list<T: Display>(mut self, name: &str, vs: impl IntoIterator<Item = T>) -> Argv {
        let vs: Vec<String> = vs.into_iter().map(|v| v.to_string()).collect();
        if !vs.is_empty() {
            self.0.push(format!("--{name}={}", vs.join(",")));
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_and_values() {
        let a = Argv::new("sweep")
            .flag("quiet", true)
            .flag("force", false)
            .opt("out", Some("-odd"))
            .opt::<u32>("width", None)
            .each("scene", ["a.obj", "b.obj"])
            .list("rays", ["primary", "ao"])
            .list::<&str>("maths", []);
        assert_eq!(a.0, ["sweep", "--quiet", "--out=-odd", "--scene=a.obj", "--scene=b.obj", "--rays=primary,ao"]);
    }
}
