//! How a measurement ended ([`Status`]): validated, failed against its reference, or skipped
//! for what the device lacks. Every command that checks or times a kernel speaks it; the
//! report layer stores it.

use serde::{Deserialize, Serialize};

/// How a measurement ended; written as `ok`, `FAILED: why` or `skipped: why`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum Status {
    /// Validated (and timed, when asked).
    #[default]
    Ok,
    /// Disagreed with its reference (naming the ray and both results), or hung: not timed.
    Failed(String),
    /// The device lacks what it needs (one line: what).
    Skipped(String),
}

impl Status {
    pub fn is_ok(&self) -> bool {
        *self == Status::Ok
    }

    pub fn is_failed(&self) -> bool {
        matches!(self, Status::Failed(_))
    }

    pub fn is_skipped(&self) -> bool {
        matches!(self, Status::Skipped(_))
    }
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Status::Ok => f.write_str("ok"),
            Status::Failed(m) => write!(f, "FAILED: {m}"),
            Status::Skipped(m) => write!(f, "skipped: {m}"),
        }
    }
}

impl From<Status> for String {
    fn from(s: Status) -> String {
        s.to_string()
    }
}

impl TryFrom<String> for Status {
    type Error = String;
    fn try_from(s: String) -> Result<Status, String> {
        if s == "ok" {
            Ok(Status::Ok)
        } else if let Some(m) = s.strip_prefix("FAILED: ") {
            Ok(Status::Failed(m.to_string()))
        } else if let Some(m) = s.strip_prefix("skipped: ") {
            Ok(Status::Skipped(m.to_string()))
        } else {
            Err(format!("status '{s}' is none of ok, FAILED: …, skipped: …"))
        }
    }
}
