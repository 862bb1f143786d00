//! Parsers for flags that carry a unit in their name: every duration on the command line is
//! in seconds (`--timeout-s`, `--wait-daemon-s`, fractions allowed), every rate in hertz.

/// A duration flag in seconds: finite and not negative (a `Duration` cannot be built from
/// anything else).
pub fn parse_seconds(text: &str) -> Result<f64, String> {
    let s: f64 = text.trim().parse().map_err(|_| format!("'{text}' is not a number of seconds"))?;
    if !s.is_finite() || s < 0.0 {
        return Err(format!("'{text}': seconds must be finite and at least 0"));
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_take_fractions_and_refuse_what_no_duration_is() {
        assert_eq!(parse_seconds("0.25"), Ok(0.25));
        assert_eq!(parse_seconds("60"), Ok(60.0));
        assert!(parse_seconds("-1").is_err());
        assert!(parse_seconds("inf").is_err());
        assert!(parse_seconds("NaN").is_err());
        assert!(parse_seconds("1000ms").is_err());
    }
}
