//! `$name` parameters: the caller's values (`-D name=value`) and `<default>`s, substituted into
//! attribute text the way Mitsuba's parser does it.
//!
//! Substitution is textual, longest name first, with no word boundary (`$a` in `x$ay` with
//! `a=Q` gives `xQy`); `\$` escapes a dollar sign; any `$` left over is an undefined parameter.
//! A caller's value wins over every `<default>`, and the first `<default>` of a name wins over
//! later ones. A caller's value that no attribute uses is an error once parsing ends.
//!
//! Substitution is bounded: `<default>`s that repeat each other grow geometrically, so one
//! attribute may expand to at most [`MAX_VALUE_BYTES`] and a document's attributes together to
//! [`MAX_TOTAL_BYTES`] (`docs/decisions/0015-limits-on-hostile-input.md`).

use std::collections::HashMap;

/// The longest attribute value substitution may produce.
pub const MAX_VALUE_BYTES: usize = 1 << 20;
/// The most text substitution may produce over a whole scene (its includes too).
pub const MAX_TOTAL_BYTES: usize = 64 << 20;

/// Why an attribute could not be substituted.
#[derive(Debug, PartialEq)]
pub(super) enum SubstituteError {
    /// `$name` is not defined.
    Undefined(String),
    /// The value would exceed [`MAX_VALUE_BYTES`], or the scene's total [`MAX_TOTAL_BYTES`].
    TooLong,
}

struct Param {
    /// `$name`
    key: String,
    value: String,
    /// Substituted at least once; defaults start as used because only unused caller values
    /// are errors.
    used: bool,
}

/// The parameters known at a point of the document, longest key first.
pub(super) struct Params {
    entries: Vec<Param>,
    /// Bytes substitution has produced so far.
    produced: usize,
}

impl Params {
    /// The caller's parameters.
    pub(super) fn new(defines: &HashMap<String, String>) -> Self {
        let mut entries: Vec<Param> =
            defines.iter().map(|(k, v)| Param { key: format!("${k}"), value: v.clone(), used: false }).collect();
        // longest first; ties by name so that the result does not depend on hash order
        entries.sort_by(|a, b| b.key.len().cmp(&a.key.len()).then_with(|| a.key.cmp(&b.key)));
        Params { entries, produced: 0 }
    }

    /// A `<default>`: added only if the name is not defined yet.
    pub(super) fn add_default(&mut self, name: &str, value: &str) {
        let key = format!("${name}");
        if self.entries.iter().any(|p| p.key == key) {
            return;
        }
        let at = self.entries.iter().position(|p| key.len() > p.key.len()).unwrap_or(self.entries.len());
        self.entries.insert(at, Param { key, value: value.to_string(), used: true });
    }

    /// `raw` with every parameter substituted.
    pub(super) fn substitute(&mut self, raw: &str) -> Result<String, SubstituteError> {
        if !raw.contains('$') {
            return Ok(raw.to_string());
        }
        let mut value = raw.to_string();
        for p in &mut self.entries {
            let mut pos = 0;
            while let Some(found) = value[pos..].find(&p.key) {
                let at = pos + found;
                if at > 0 && value.as_bytes()[at - 1] == b'\\' {
                    pos = at + p.key.len();
                } else {
                    if value.len() - p.key.len() + p.value.len() > MAX_VALUE_BYTES {
                        return Err(SubstituteError::TooLong);
                    }
                    value.replace_range(at..at + p.key.len(), &p.value);
                    p.used = true;
                    pos = at + p.value.len();
                }
            }
        }
        let mut pos = 0;
        while let Some(found) = value[pos..].find('$') {
            let at = pos + found;
            if at > 0 && value.as_bytes()[at - 1] == b'\\' {
                pos = at + 1;
                continue;
            }
            let name: String = value[at + 1..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            return Err(SubstituteError::Undefined(name));
        }
        self.produced += value.len();
        if self.produced > MAX_TOTAL_BYTES {
            return Err(SubstituteError::TooLong);
        }
        Ok(value.replace("\\$", "$"))
    }

    /// Caller parameters no attribute used, by name.
    pub(super) fn unused(&self) -> Vec<(&str, &str)> {
        let mut out: Vec<(&str, &str)> =
            self.entries.iter().filter(|p| !p.used).map(|p| (&p.key[1..], p.value.as_str())).collect();
        out.sort();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(pairs: &[(&str, &str)]) -> Params {
        Params::new(&pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect())
    }

    #[test]
    fn params_substitute_longest_key_first_without_word_boundary() {
        let mut p = params(&[("a", "Q"), ("ab", "R")]);
        assert_eq!(p.substitute("x$ay").unwrap(), "xQy");
        assert_eq!(p.substitute("$ab/$a").unwrap(), "R/Q");
        assert!(p.unused().is_empty());
    }

    #[test]
    fn params_escaped_dollar_is_kept_literally() {
        let mut p = params(&[("a", "Q")]);
        assert_eq!(p.substitute(r"\$a and $a").unwrap(), "$a and Q");
        assert_eq!(p.substitute(r"cost \$5").unwrap(), "cost $5");
    }

    #[test]
    fn params_undefined_name_is_reported() {
        let mut p = params(&[]);
        assert_eq!(p.substitute("1.5 * $radius_2!"), Err(SubstituteError::Undefined("radius_2".to_string())));
    }

    #[test]
    fn params_caller_and_first_default_win() {
        let mut p = params(&[("spp", "16")]);
        p.add_default("spp", "4");
        p.add_default("res", "64");
        p.add_default("res", "128");
        assert_eq!(p.substitute("$spp $res").unwrap(), "16 64");
    }

    #[test]
    fn params_unused_caller_values_are_listed_but_defaults_never() {
        let mut p = params(&[("used", "1"), ("spare", "2")]);
        p.add_default("never", "3");
        p.substitute("$used").unwrap();
        assert_eq!(p.unused(), vec![("spare", "2")]);
    }
}
