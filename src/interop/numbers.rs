//! Numbers as text every consumer parses back exactly.
//!
//! Rust prints the shortest decimal that round-trips, but `1e-20` is a string to PyYAML (YAML
//! 1.1 wants a dot and a signed exponent) and `1` is an integer to some readers. [`num`] always
//! writes a dot and, in scientific notation, a signed exponent: valid YAML 1.1 and 1.2, JSON,
//! OpenCV FileStorage and `strtod`, and still the shortest round-trip digits.

/// `v` as a float literal that parses back to exactly `v` (non-finite values as `.nan`/`.inf`
/// never occur: every caller writes validated, finite geometry).
pub fn num(v: f64) -> String {
    if v == 0.0 {
        return "0.0".into();
    }
    let a = v.abs();
    if (1e-5..1e16).contains(&a) {
        let s = format!("{v}");
        if s.contains('.') { s } else { format!("{s}.0") }
    } else {
        let s = format!("{v:e}");
        let (mantissa, exponent) = s.split_once('e').unwrap_or((&s, "0"));
        let mantissa = if mantissa.contains('.') {
            mantissa.to_string()
        } else {
            format!("{mantissa}.0")
        };
        let exponent = if exponent.starts_with('-') {
            exponent.to_string()
        } else {
            format!("+{exponent}")
        };
        format!("{mantissa}e{exponent}")
    }
}

/// `[a, b, c]` with [`num`].
pub fn list(values: &[f64]) -> String {
    let inner: Vec<String> = values.iter().map(|&v| num(v)).collect();
    format!("[{}]", inner.join(", "))
}

/// Space-separated, for KITTI and command lines.
pub fn spaced(values: &[f64]) -> String {
    let inner: Vec<String> = values.iter().map(|&v| num(v)).collect();
    inner.join(" ")
}

/// Row-major 3×4 `[R | t]` of a transform.
pub fn rows_3x4(t: crate::geometry::Rigid) -> [f64; 12] {
    let r = t.to_rows();
    let mut out = [0.0; 12];
    for i in 0..3 {
        out[i * 4..i * 4 + 4].copy_from_slice(&r[i]);
    }
    out
}

/// Row-major 4×4 of a transform.
pub fn rows_4x4(t: crate::geometry::Rigid) -> [f64; 16] {
    let r = t.to_rows();
    let mut out = [0.0; 16];
    for i in 0..4 {
        out[i * 4..i * 4 + 4].copy_from_slice(&r[i]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_number_round_trips_and_looks_like_a_float() {
        for v in [
            0.0, 1.0, -2.0, 0.1, 1e-20, -3.5e-9, 1.5e16, 1e300, 123456.789, 6.123e-17, 1e-5,
            9.99e15,
        ] {
            let s = num(v);
            assert_eq!(s.parse::<f64>().unwrap(), v, "{s}");
            assert!(s.contains('.'), "{s}");
            if let Some((_, e)) = s.split_once('e') {
                assert!(e.starts_with('-') || e.starts_with('+'), "{s}");
            }
            // serde_yaml (YAML 1.2) and serde_json read it as the same float.
            let y: f64 = serde_yaml::from_str(&s).unwrap();
            let j: f64 = serde_json::from_str(&s).unwrap();
            assert_eq!((y, j), (v, v), "{s}");
        }
        assert_eq!(list(&[1.0, 0.5]), "[1.0, 0.5]");
        assert_eq!(spaced(&[1.0, -2.0]), "1.0 -2.0");
    }
}
