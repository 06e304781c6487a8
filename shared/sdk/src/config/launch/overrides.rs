//! Overrides: `--set KEY=VALUE` and `--fault` from the command line, and merging a launch file
//! over the scenario's defaults.

use crate::config::error::LaunchError;

/// One `--set KEY=VALUE` from the command line.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    pub key: String,
    pub value: toml::Value,
    /// As the user typed it, for error messages.
    pub text: String,
    /// Appends `value` to the array at `key` (a `--fault`) instead of setting it.
    pub append: bool,
}

impl Override {
    /// Parses `KEY=VALUE`. The value is read as TOML (`0.05`, `true`, `[1, 2]`, `"x"`);
    /// anything that is not valid TOML is taken as a plain string (`no-bias`).
    pub fn parse(text: &str) -> Result<Self, LaunchError> {
        let origin = format!("--set {text}");
        let Some((key, raw)) = text.split_once('=') else {
            return Err(LaunchError::new(origin, None, "expected KEY=VALUE, for example sensors.encoder.bias=0.05"));
        };
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(LaunchError::new(origin, None, "the key must be a dotted path such as estimator.kind"));
        }
        let raw = raw.trim();
        let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(raw.to_owned()));
        Ok(Self { key: key.to_owned(), value, text: text.to_owned(), append: false })
    }

    /// Parses a `--fault` text (see [`crate::config::faults::FAULT_SYNTAX`]) into an entry appended to
    /// the launch file's `faults` list.
    pub fn fault(text: &str) -> Result<Self, LaunchError> {
        let origin = format!("--fault {text}");
        let spec = crate::config::faults::parse_fault(text).map_err(|e| LaunchError::new(&origin, None, e))?;
        let value = toml::Value::try_from(&spec).expect("a fault always converts to TOML");
        Ok(Self { key: "faults".into(), value, text: text.to_owned(), append: true })
    }

    /// Where the value came from, for error messages.
    pub(super) fn origin(&self) -> String {
        if self.append { format!("--fault {}", self.text) } else { format!("--set {}", self.text) }
    }
}

/// Deep-merges `over` into `base`: tables merge key by key, anything else replaces.
pub fn merge(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Sets a dotted key, or appends to the array at it; returns the key that was set (for an
/// append, with the new element's index). A number in the path indexes an array
/// (`faults.0.delay_ticks`). An integer written where the defaults hold a float is taken as that
/// float, so `--set duration_s=30` works.
pub(super) fn set_dotted(document: &mut toml::Table, o: &Override) -> Result<String, String> {
    let parts: Vec<&str> = o.key.split('.').collect();
    let (last, parents) = parts.split_last().expect("keys are checked to be non-empty");
    let mut root = toml::Value::Table(std::mem::take(document));
    let result = (|| {
        let mut value = &mut root;
        for (i, part) in parents.iter().enumerate() {
            let path = parts[..i].join(".");
            value = match value {
                toml::Value::Table(t) => {
                    t.entry(part.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()))
                }
                toml::Value::Array(items) => {
                    let len = items.len();
                    let index = part.parse::<usize>().ok().filter(|i| *i < len);
                    index.and_then(|i| items.get_mut(i)).ok_or_else(|| {
                        format!("`{path}` is a list of {len}; index it with 0 to {}", len.saturating_sub(1))
                    })?
                }
                _ => return Err(format!("`{path}` is a value, not a table, so it has no key `{part}`")),
            };
        }
        // One item of a list (`model.inertia_kg_m2.1`).
        if let toml::Value::Array(items) = value
            && !o.append
        {
            let len = items.len();
            let item = last.parse::<usize>().ok().and_then(|i| items.get_mut(i)).ok_or_else(|| {
                format!("`{}` is a list of {len}; index it with 0 to {}", parents.join("."), len.saturating_sub(1))
            })?;
            *item = match (&*item, &o.value) {
                (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
                (_, v) => v.clone(),
            };
            return Ok(o.key.clone());
        }
        let toml::Value::Table(table) = value else {
            return Err(format!("`{}` is not a table, so it has no key `{last}`", parents.join(".")));
        };
        if o.append {
            let items = table.entry(last.to_string()).or_insert_with(|| toml::Value::Array(vec![]));
            let toml::Value::Array(items) = items else { return Err(format!("`{}` is not a list", o.key)) };
            items.push(o.value.clone());
            return Ok(format!("{}.{}", o.key, items.len() - 1));
        }
        let value = match (table.get(*last), &o.value) {
            (Some(toml::Value::Float(_)), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
            (Some(toml::Value::Table(_)), v) if !v.is_table() => {
                return Err(format!("`{}` is a table; set one of its keys instead", o.key));
            }
            (_, v) => v.clone(),
        };
        table.insert(last.to_string(), value);
        Ok(o.key.clone())
    })();
    let toml::Value::Table(table) = root else { unreachable!("the root stays a table") };
    *document = table;
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn override_parsing() {
        assert_eq!(Override::parse("a.b=1.5").unwrap().value, toml::Value::Float(1.5));
        assert_eq!(Override::parse("a=no-bias").unwrap().value, toml::Value::String("no-bias".into()));
        assert_eq!(Override::parse("a=[1, 2]").unwrap().value.as_array().unwrap().len(), 2);
        assert!(Override::parse("novalue").is_err());
        assert!(Override::parse("a..b=1").is_err());
    }
}
