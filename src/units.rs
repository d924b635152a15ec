//! Durations as users write them (`90`, `90s`, `8m`, `1h30m`, `2.5m`), range-checked where
//! they are parsed: a duration is finite, positive and at most [`MAX_SECONDS`] (a week), so
//! every later conversion (`Duration`, a fence wait in nanoseconds) is exact and cannot panic.

/// The longest duration any parameter takes: one week.
pub const MAX_SECONDS: f64 = 7.0 * 24.0 * 3600.0;

/// Checks seconds given as a number (a flag or a TOML key named `what`).
pub fn check_seconds(what: &str, secs: f64) -> Result<f64, String> {
    if !secs.is_finite() || secs <= 0.0 {
        return Err(format!("{what}: {secs} is not a positive, finite number of seconds"));
    }
    if secs > MAX_SECONDS {
        return Err(format!("{what}: {secs} s is more than a week ({MAX_SECONDS} s), the longest allowed"));
    }
    Ok(secs)
}

/// Parses a duration: a number of seconds, or numbers each followed by `h`, `m` or `s`
/// (`1h30m`, `8m`, `2.5m`, `45s`); returns seconds, checked by [`check_seconds`].
pub fn parse_duration(what: &str, text: &str) -> Result<f64, String> {
    let t = text.trim();
    let bad = || format!("{what}: '{text}' is not a duration (seconds, or e.g. 90s, 8m, 1h30m)");
    if t.is_empty() {
        return Err(bad());
    }
    if let Ok(x) = t.parse::<f64>() {
        // Plain numbers only: "inf" and "nan" parse as floats too, and are refused below.
        if t.bytes().all(|b| b.is_ascii_digit() || b == b'.') {
            return check_seconds(what, x);
        }
        return Err(bad());
    }
    let mut total = 0.0;
    let mut num = String::new();
    let mut last_unit = 4; // h = 3, m = 2, s = 1: each unit once, largest first
    for c in t.chars() {
        match c {
            '0'..='9' | '.' => num.push(c),
            'h' | 'm' | 's' => {
                let unit = match c {
                    'h' => 3,
                    'm' => 2,
                    _ => 1,
                };
                let x: f64 = num.parse().map_err(|_| bad())?;
                if unit >= last_unit {
                    return Err(bad());
                }
                last_unit = unit;
                total += x * [0.0, 1.0, 60.0, 3600.0][unit];
                num.clear();
            }
            _ => return Err(bad()),
        }
    }
    if !num.is_empty() {
        return Err(bad());
    }
    check_seconds(what, total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse_and_are_range_checked() {
        for (t, s) in [("90", 90.0), ("90s", 90.0), ("8m", 480.0), ("1h30m", 5400.0), ("2.5m", 150.0), ("1m5s", 65.0)] {
            assert_eq!(parse_duration("--budget", t), Ok(s), "{t}");
        }
        for t in ["", "0", "-5", "inf", "nan", "1e300", "5x", "m", "1m1h", "1s1s", "1.2.3s", "10m5", "8d"] {
            let e = parse_duration("--budget", t).expect_err(t);
            assert!(e.starts_with("--budget: "), "{t}: {e}");
        }
        assert!(parse_duration("--budget", "169h").unwrap_err().contains("more than a week"));
        assert!(check_seconds("kernel_timeout", 1e300).is_err());
        assert!(check_seconds("kernel_timeout", f64::INFINITY).is_err());
        assert!(check_seconds("kernel_timeout", f64::NAN).is_err());
        assert_eq!(check_seconds("kernel_timeout", 600.0), Ok(600.0));
    }
}
