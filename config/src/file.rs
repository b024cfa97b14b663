//! Reading a settings file: a flat TOML table whose values are turned into the text a flag
//! would carry on the command line (arrays into several values), each with the line of its
//! key for error messages.

use crate::ConfigError;
use std::path::{Path, PathBuf};
use toml::de::{DeTable, DeValue};

/// One `key = value` of the file.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Entry {
    /// The key (a long flag's name).
    pub key: String,
    /// Line of the key, from 1.
    pub line: usize,
    /// The value as command-line text; several for an array.
    pub values: Vec<String>,
    /// Whether the value was an array.
    pub array: bool,
}

/// A settings file's entries, in the file's order.
#[derive(Clone, Debug)]
pub(crate) struct SettingsFile {
    pub path: PathBuf,
    pub entries: Vec<Entry>,
}

impl SettingsFile {
    /// Reads and parses `path`.
    pub fn load(path: &Path) -> Result<SettingsFile, ConfigError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.to_path_buf(), source })?;
        Self::parse(path, &text)
    }

    /// Parses `text`, the contents of `path`.
    pub fn parse(path: &Path, text: &str) -> Result<SettingsFile, ConfigError> {
        let doc = DeTable::parse(text)
            .map_err(|e| ConfigError::Syntax { path: path.to_path_buf(), message: e.to_string().trim_end().into() })?;
        let mut entries = Vec::new();
        for (key, value) in doc.get_ref().iter() {
            let line = line_of(text, key.span().start);
            let bad = |message: String| ConfigError::BadValue {
                path: path.to_path_buf(),
                line,
                key: key.get_ref().to_string(),
                message,
            };
            let (values, array) = match value.get_ref() {
                DeValue::Array(items) => {
                    (items.iter().map(|v| scalar(v.get_ref())).collect::<Result<Vec<_>, _>>().map_err(bad)?, true)
                }
                // a `[section]` would be a natural guess, so say what is expected instead
                DeValue::Table(_) => {
                    return Err(bad("a table; settings are top-level keys named as the long flags".into()));
                }
                v => (vec![scalar(v).map_err(bad)?], false),
            };
            entries.push(Entry { key: key.get_ref().to_string(), line, values, array });
        }
        entries.sort_by_key(|e| e.line);
        Ok(SettingsFile { path: path.to_path_buf(), entries })
    }
}

/// A scalar as a flag's text: strings as they are, numbers in decimal, booleans as
/// `true`/`false`.
fn scalar(value: &DeValue) -> Result<String, String> {
    Ok(match value {
        DeValue::String(s) => s.to_string(),
        DeValue::Integer(i) => match i64::from_str_radix(i.as_str(), i.radix()) {
            Ok(n) => n.to_string(),
            Err(_) => u64::from_str_radix(i.as_str(), i.radix()).map_err(|e| e.to_string())?.to_string(),
        },
        DeValue::Float(f) => f.as_str().to_string(),
        DeValue::Boolean(b) => b.to_string(),
        DeValue::Datetime(d) => d.to_string(),
        DeValue::Array(_) | DeValue::Table(_) => return Err(format!("a nested {}", value.type_str())),
    })
}

/// The 1-based line of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<Entry>, ConfigError> {
        SettingsFile::parse(Path::new("farm.toml"), text).map(|f| f.entries)
    }

    #[test]
    fn values_become_flag_text_with_their_lines() {
        let entries = parse("# farm\nlisten = \"0.0.0.0:7878\"\nlease-timeout = 1.5\n\nmax-tiles = 0x10\ninsecure = true\nupdates = [1, 4]\n").unwrap();
        let got: Vec<_> = entries.iter().map(|e| (e.key.as_str(), e.line, e.values.join(","), e.array)).collect();
        assert_eq!(
            got,
            [
                ("listen", 2, "0.0.0.0:7878".to_string(), false),
                ("lease-timeout", 3, "1.5".into(), false),
                ("max-tiles", 5, "16".into(), false),
                ("insecure", 6, "true".into(), false),
                ("updates", 7, "1,4".into(), true),
            ]
        );
    }

    #[test]
    fn syntax_errors_and_tables_name_the_file_and_line() {
        let e = parse("listen = \"a\"\nlisten = \"b\"\n").unwrap_err().to_string();
        assert!(e.contains("farm.toml") && e.contains("line 2"), "{e}");
        let e = parse("a = 1\n[serve]\nlisten = \"x\"\n").unwrap_err().to_string();
        assert!(e.contains("farm.toml, line 2: `serve`: a table"), "{e}");
        let e = parse("a = [[1]]\n").unwrap_err().to_string();
        assert!(e.contains("line 1: `a`: a nested array"), "{e}");
    }
}
