//! `$name` parameters: the caller's values (`-D name=value`) and `<default>`s, substituted into
//! attribute text the way Mitsuba's parser does it.
//!
//! Substitution is textual, longest name first, with no word boundary (`$a` in `x$ay` with
//! `a=Q` gives `xQy`); `\$` escapes a dollar sign; any `$` left over is an undefined parameter.
//! A caller's value wins over every `<default>`, and the first `<default>` of a name wins over
//! later ones. A caller's value that no attribute uses is an error once parsing ends.
//!
//! Mitsuba replaces each name in turn over the whole value, so text one name put in can hold
//! another. Trying every name on every attribute costs names × bytes, so the names present are
//! found instead by walking a trie of names from each `$` (names hold no `$`, so the walks
//! together read each byte once), and only those names take their turn.
//!
//! Substitution is bounded: `<default>`s that repeat each other grow geometrically, so one
//! attribute may expand to at most [`MAX_VALUE_BYTES`] and a document's attributes together to
//! [`MAX_TOTAL_BYTES`] (`docs/decisions/0015-limits-on-hostile-input.md`); a scene has at most
//! [`MAX_PARAMETERS`] names of at most [`MAX_NAME_BYTES`] each.

use std::cmp::Reverse;
use std::collections::{BTreeSet, HashMap};

/// The longest attribute value substitution may produce.
pub const MAX_VALUE_BYTES: usize = 1 << 20;
/// The most text substitution may produce over a whole scene (its includes too).
pub const MAX_TOTAL_BYTES: usize = 64 << 20;
/// The most parameters (caller values and `<default>`s) a scene may have.
pub const MAX_PARAMETERS: usize = 4096;
/// The longest parameter name.
pub const MAX_NAME_BYTES: usize = 256;

/// Why an attribute could not be substituted.
#[derive(Debug, PartialEq)]
pub(super) enum SubstituteError {
    /// `$name` is not defined.
    Undefined(String),
    /// The value would exceed [`MAX_VALUE_BYTES`], or the scene's total [`MAX_TOTAL_BYTES`].
    TooLong,
}

/// When a parameter takes its turn: longer names first; among names of one length, caller
/// values by name, then `<default>`s in document order.
type Turn = (Reverse<usize>, u32);

struct Param {
    /// `$name`
    key: String,
    value: String,
    /// Substituted at least once; defaults start as used because only unused caller values
    /// are errors.
    used: bool,
    turn: Turn,
}

/// The names known, as a trie over their bytes (without the `$`).
#[derive(Default)]
struct Trie {
    /// (node, byte) → child node; node 0 is the root.
    edges: HashMap<(u32, u8), u32>,
    /// Per node, the parameter whose name ends there.
    ends: Vec<Option<u32>>,
}

impl Trie {
    fn insert(&mut self, name: &[u8], param: u32) {
        if self.ends.is_empty() {
            self.ends.push(None);
        }
        let mut node = 0;
        for &b in name {
            let next = self.ends.len() as u32;
            node = *self.edges.entry((node, b)).or_insert(next);
            if node == next {
                self.ends.push(None);
            }
        }
        self.ends[node as usize] = Some(param);
    }

    /// Every parameter whose name starts `text`.
    fn prefixes(&self, text: &[u8], mut found: impl FnMut(u32)) {
        let mut node = 0;
        for &b in text {
            match self.edges.get(&(node, b)) {
                Some(&next) => node = next,
                None => return,
            }
            if let Some(p) = self.ends[node as usize] {
                found(p);
            }
        }
    }
}

/// The parameters known at a point of the document.
pub(super) struct Params {
    entries: Vec<Param>,
    trie: Trie,
    /// Bytes substitution has produced so far.
    produced: usize,
}

/// Why a parameter name is refused, if it is.
fn check_name(name: &str) -> Result<(), String> {
    if name.len() > MAX_NAME_BYTES {
        return Err(format!("parameter names are at most {MAX_NAME_BYTES} bytes long"));
    }
    if name.contains('$') {
        return Err(format!("parameter name \"{name}\" contains '$'"));
    }
    Ok(())
}

impl Params {
    /// The caller's parameters.
    pub(super) fn new(defines: &HashMap<String, String>) -> Result<Self, String> {
        let mut names: Vec<(&String, &String)> = defines.iter().collect();
        // by name, so that the order does not depend on hash order
        names.sort();
        let mut params = Params { entries: vec![], trie: Trie::default(), produced: 0 };
        for (name, value) in names {
            params.add(name, value, false)?;
        }
        Ok(params)
    }

    fn add(&mut self, name: &str, value: &str, used: bool) -> Result<(), String> {
        check_name(name)?;
        if self.entries.len() >= MAX_PARAMETERS {
            return Err(format!("a scene may have at most {MAX_PARAMETERS} parameters"));
        }
        let id = self.entries.len() as u32;
        let turn = (Reverse(name.len() + 1), id);
        self.entries.push(Param { key: format!("${name}"), value: value.to_string(), used, turn });
        self.trie.insert(name.as_bytes(), id);
        Ok(())
    }

    /// A `<default>`: added only if the name is not defined yet.
    pub(super) fn add_default(&mut self, name: &str, value: &str) -> Result<(), String> {
        let key = format!("${name}");
        if self.entries.iter().any(|p| p.key == key) {
            return Ok(());
        }
        self.add(name, value, true)
    }

    /// Queues the parameters named after each `$` in `text[from..to]` (and after the last `$`
    /// before `from`, whose name may run into the range) that take their turn after `after`.
    fn queue(&self, text: &str, from: usize, to: usize, after: Option<Turn>, queue: &mut BTreeSet<(Turn, u32)>) {
        let bytes = text.as_bytes();
        // a name is at most MAX_NAME_BYTES long, so no `$` further back can reach `from`
        let lo = from.saturating_sub(MAX_NAME_BYTES + 1);
        let start = bytes[lo..from].iter().rposition(|&b| b == b'$').map_or(from, |i| lo + i);
        for (i, _) in text[start..to].match_indices('$') {
            let rest = &bytes[start + i + 1..];
            // the trie has no `$`: a walk stops at the next one, or after the longest name
            self.trie.prefixes(&rest[..rest.len().min(MAX_NAME_BYTES)], |p| {
                let turn = self.entries[p as usize].turn;
                if after.is_none_or(|a| turn > a) {
                    queue.insert((turn, p));
                }
            });
        }
    }

    /// `raw` with every parameter substituted.
    pub(super) fn substitute(&mut self, raw: &str) -> Result<String, SubstituteError> {
        if !raw.contains('$') {
            return Ok(raw.to_string());
        }
        let mut value = raw.to_string();
        let mut queue = BTreeSet::new();
        self.queue(&value, 0, value.len(), None, &mut queue);
        while let Some((turn, id)) = queue.pop_first() {
            let inserted = self.replace_all(id as usize, &mut value)?;
            for (from, to) in inserted {
                self.queue(&value, from, to, Some(turn), &mut queue);
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

    /// Replaces every unescaped `$name` of parameter `id` in `value`; returns the byte ranges
    /// put in.
    fn replace_all(&mut self, id: usize, value: &mut String) -> Result<Vec<(usize, usize)>, SubstituteError> {
        let p = &mut self.entries[id];
        let mut inserted = Vec::new();
        let mut pos = 0;
        while let Some(found) = value[pos..].find(&p.key) {
            let at = pos + found;
            if at > 0 && value.as_bytes()[at - 1] == b'\\' {
                pos = at + p.key.len();
                continue;
            }
            if value.len() - p.key.len() + p.value.len() > MAX_VALUE_BYTES {
                return Err(SubstituteError::TooLong);
            }
            value.replace_range(at..at + p.key.len(), &p.value);
            p.used = true;
            pos = at + p.value.len();
            inserted.push((at, pos));
        }
        Ok(inserted)
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
        Params::new(&pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()).unwrap()
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
        p.add_default("spp", "4").unwrap();
        p.add_default("res", "64").unwrap();
        p.add_default("res", "128").unwrap();
        assert_eq!(p.substitute("$spp $res").unwrap(), "16 64");
    }

    #[test]
    fn params_unused_caller_values_are_listed_but_defaults_never() {
        let mut p = params(&[("used", "1"), ("spare", "2")]);
        p.add_default("never", "3").unwrap();
        p.substitute("$used").unwrap();
        assert_eq!(p.unused(), vec![("spare", "2")]);
    }
}
