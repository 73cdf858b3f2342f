//! Names as text every consumer parses back unchanged.
//!
//! Sensor and frame names come from users' files and logs, so they can hold anything: a `:` or
//! `#` that YAML would read as structure, a word YAML 1.1 reads as a boolean (`on`, `no`), a
//! newline that would end a comment and turn the rest into content. [`yaml_str`] writes a
//! YAML scalar that reads back as the same string (plain when that is safe, else a
//! double-quoted JSON string, which is valid YAML 1.1 and 1.2); [`comment`] makes text safe
//! inside a one-line `#` comment.

/// `s` as a YAML scalar that PyYAML, serde_yaml and OpenCV read back as the string `s`.
pub fn yaml_str(s: &str) -> String {
    let plain_char = |c: char| c.is_ascii_alphanumeric() || "_./-".contains(c);
    let first_ok = s
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_' || c == '/');
    // Words YAML 1.1 resolves to booleans or null.
    let special = [
        "y", "yes", "n", "no", "true", "false", "on", "off", "null", "nan", "inf",
    ]
    .contains(&s.to_ascii_lowercase().as_str());
    if first_ok && !special && s.chars().all(plain_char) {
        s.to_string()
    } else {
        // A JSON string literal is a YAML double-quoted scalar.
        serde_json::to_string(s).unwrap_or_else(|_| format!("\"{}\"", s.escape_default()))
    }
}

/// Text safe inside a one-line `#` comment: control characters become spaces.
pub fn comment(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_reads_back_as_itself() {
        for s in [
            "front_camera",
            "/cam0/image_raw",
            "cam: 0",
            "# not a comment",
            "on",
            "No",
            "123",
            "1e3",
            "- item",
            "[a]",
            "{b}",
            "tab\there",
            "new\nline",
            "quote\"s and 'apostrophes'",
            "ünïcødé",
            "",
            "@at",
            "*alias",
            "&anchor",
            "!tag",
            "%percent",
            "trailing ",
        ] {
            let text = format!("key: {}\n{}: 1\n", yaml_str(s), yaml_str(s));
            let y: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
            assert_eq!(y["key"].as_str(), Some(s), "{s:?} as {}", yaml_str(s));
            let m = y.as_mapping().unwrap();
            assert!(
                m.contains_key(serde_yaml::Value::String(s.into())),
                "{s:?} key"
            );
        }
        assert_eq!(yaml_str("front_camera"), "front_camera");
        assert_eq!(comment("a\nb\rc"), "a b c");
    }
}
