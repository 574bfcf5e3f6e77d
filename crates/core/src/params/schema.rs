//! What one parameter is ([`Schema`]: name, type, range, unit, default,
//! description) and how a value given for it is checked and converted.
//! Every table, the core's and any written outside Rust, goes through
//! [`Schema::convert`] and [`Schema::parse`], so a value means the same
//! wherever it is given.

use std::fmt;

use super::range::{format_number, Range};
use crate::error::{Error, Result};

/// A parameter value, typed. `None` switches an optional feature off.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    None,
    Bool(bool),
    Integer(i64),
    Float(f64),
    Text(String),
}

impl fmt::Display for Value {
    /// As the command line would write it (text quoted, for messages).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::None => write!(f, "none"),
            Value::Bool(b) => write!(f, "{b}"),
            Value::Integer(i) => write!(f, "{i}"),
            Value::Float(x) => write!(f, "{}", format_number(*x)),
            Value::Text(s) => write!(f, "'{s}'"),
        }
    }
}

/// The type of a parameter.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind {
    Bool,
    Integer,
    Float,
    /// One of these strings.
    Choice(Vec<String>),
}

/// Spellings of a boolean on the command line (case-insensitive).
pub const TRUE_WORDS: &[&str] = &["true", "yes", "1"];
pub const FALSE_WORDS: &[&str] = &["false", "no", "0"];

/// One row of a parameter table, without access to any struct: what the
/// bindings, the CLI and the docs read.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    pub name: String,
    pub kind: Kind,
    /// Whether `none` is a value (an optional feature, off when none).
    pub optional: bool,
    /// Allowed numbers (integer and float kinds only).
    pub range: Range,
    /// Unit of the value, e.g. `m`, `s`, `m^2/s^3`; empty when it has none.
    pub unit: String,
    /// One line: what the parameter does.
    pub description: String,
    pub default: Value,
}

impl Schema {
    /// The type as the docs show it: `bool`, `integer`, `float`, `float or none`, `fast | naive`.
    pub fn type_name(&self) -> String {
        let base = match &self.kind {
            Kind::Bool => "bool".to_string(),
            Kind::Integer => "integer".to_string(),
            Kind::Float => "float".to_string(),
            Kind::Choice(choices) => choices.join(" | "),
        };
        if self.optional {
            format!("{base} or none")
        } else {
            base
        }
    }

    /// The range as the docs show it (`-` where there is none to speak of).
    pub fn range_text(&self) -> String {
        match self.kind {
            Kind::Integer | Kind::Float if !self.range.is_any() => self.range.to_string(),
            Kind::Float => "finite".to_string(),
            _ => "-".to_string(),
        }
    }

    /// What a value must be, for messages: "an integer >= 1", "true or false".
    fn expected(&self) -> String {
        let numeric = |what: &str| {
            if self.range.is_any() {
                format!("a finite {what}")
            } else {
                let range = self.range.to_string();
                let joiner = if range.starts_with(['[', '(']) { " in " } else { " " };
                format!("a{} {what}{joiner}{range}", if what == "integer" { "n" } else { "" })
            }
        };
        let base = match &self.kind {
            Kind::Bool => format!("true or false ({}, {})", TRUE_WORDS.join("/"), FALSE_WORDS.join("/")),
            Kind::Integer => numeric("integer"),
            Kind::Float => numeric("float"),
            Kind::Choice(choices) => format!("one of {}", choices.join(", ")),
        };
        if self.optional {
            format!("{base}, or none")
        } else {
            base
        }
    }

    fn error(&self, given: &Value) -> Error {
        Error::Parameter { name: self.name.clone(), reason: format!("expected {}, got {given}", self.expected()) }
    }

    /// Checks a typed value and converts it to this parameter's kind: an
    /// integer given for a float, a whole float for an integer, 0/1 for a
    /// bool; text is read as [`Schema::parse`] reads it (a value from a
    /// TOML or JSON file or the command line means the same). Errors name
    /// the parameter, what it must be and the value given.
    pub fn convert(&self, value: &Value) -> Result<Value> {
        let out = match (&self.kind, value) {
            (Kind::Choice(_), Value::Text(_)) => return self.parse_choice(value),
            (_, Value::Text(text)) => return self.parse(text),
            (_, Value::None) if self.optional => Value::None,
            (Kind::Bool, Value::Bool(b)) => Value::Bool(*b),
            (Kind::Bool, Value::Integer(i @ (0 | 1))) => Value::Bool(*i == 1),
            (Kind::Integer, Value::Integer(i)) => Value::Integer(*i),
            // Whole numbers only, and within i64 (a float of 2^63 is not).
            (Kind::Integer, Value::Float(x)) if x.fract() == 0.0 && x.abs() < 9.2e18 => Value::Integer(*x as i64),
            (Kind::Float, Value::Integer(i)) => Value::Float(*i as f64),
            (Kind::Float, Value::Float(x)) => Value::Float(*x),
            _ => return Err(self.error(value)),
        };
        let in_range = match out {
            Value::Integer(i) => self.range.contains(i as f64),
            Value::Float(x) => self.range.contains(x),
            _ => true,
        };
        if in_range {
            Ok(out)
        } else {
            Err(self.error(value))
        }
    }

    fn parse_choice(&self, value: &Value) -> Result<Value> {
        let (Kind::Choice(choices), Value::Text(text)) = (&self.kind, value) else {
            return Err(self.error(value));
        };
        let text = text.trim();
        // Exact first; then case-insensitively, giving the table's spelling.
        if let Some(c) = choices.iter().find(|c| c.as_str() == text).or_else(|| choices.iter().find(|c| c.eq_ignore_ascii_case(text))) {
            return Ok(Value::Text(c.clone()));
        }
        if self.optional && text.eq_ignore_ascii_case("none") {
            return Ok(Value::None);
        }
        Err(self.error(value))
    }

    /// Reads a value from text (`--param NAME=TEXT`): booleans as
    /// true/false/yes/no/1/0 (any case), `none` for an optional parameter,
    /// numbers as Rust reads them (`1e-6`, `inf`), choices by name.
    pub fn parse(&self, text: &str) -> Result<Value> {
        let trimmed = text.trim();
        let given = Value::Text(text.to_string());
        if self.optional && trimmed.eq_ignore_ascii_case("none") {
            return Ok(Value::None);
        }
        let lower = trimmed.to_ascii_lowercase();
        match &self.kind {
            Kind::Bool if TRUE_WORDS.contains(&lower.as_str()) => Ok(Value::Bool(true)),
            Kind::Bool if FALSE_WORDS.contains(&lower.as_str()) => Ok(Value::Bool(false)),
            Kind::Bool => Err(self.error(&given)),
            Kind::Integer => match (trimmed.parse::<i64>(), trimmed.parse::<f64>()) {
                (Ok(i), _) => self.convert(&Value::Integer(i)),
                (_, Ok(x)) if x.fract() == 0.0 => self.convert(&Value::Float(x)).map_err(|_| self.error(&given)),
                _ => Err(self.error(&given)),
            },
            Kind::Float => match trimmed.parse::<f64>() {
                // Out of range: the number as read (-1, inf), not the text.
                Ok(x) => self.convert(&Value::Float(x)),
                Err(_) => Err(self.error(&given)),
            },
            Kind::Choice(_) => self.parse_choice(&given),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schema(kind: Kind, range: Range, optional: bool) -> Schema {
        Schema {
            name: "x".into(),
            kind,
            optional,
            range,
            unit: String::new(),
            description: String::new(),
            default: Value::None,
        }
    }

    fn reason(result: Result<Value>) -> String {
        match result {
            Err(Error::Parameter { name, reason }) => {
                assert_eq!(name, "x");
                reason
            }
            other => panic!("expected a parameter error, got {other:?}"),
        }
    }

    #[test]
    fn booleans_accept_every_spelling() {
        let s = schema(Kind::Bool, Range::ANY, false);
        for word in ["true", "True", "YES", "yes", "1", " true "] {
            assert_eq!(s.parse(word).unwrap(), Value::Bool(true), "{word}");
        }
        for word in ["false", "FALSE", "no", "No", "0"] {
            assert_eq!(s.parse(word).unwrap(), Value::Bool(false), "{word}");
        }
        let r = reason(s.parse("maybe"));
        assert!(r.contains("true or false") && r.contains("'maybe'"), "{r}");
        // "false" given as text in a dict is false, not a truthy string.
        assert_eq!(s.convert(&Value::Text("false".into())).unwrap(), Value::Bool(false));
        assert_eq!(s.convert(&Value::Integer(0)).unwrap(), Value::Bool(false));
        assert!(s.convert(&Value::Integer(2)).is_err());
        assert!(s.convert(&Value::Float(1.0)).is_err());
    }

    #[test]
    fn integers_are_whole_and_in_range() {
        let s = schema(Kind::Integer, Range::at_least(1.0), false);
        assert_eq!(s.parse("5").unwrap(), Value::Integer(5));
        assert_eq!(s.parse("1e5").unwrap(), Value::Integer(100_000));
        let r = reason(s.parse("-1"));
        assert!(r.contains("an integer >= 1") && r.contains("-1"), "{r}");
        assert!(reason(s.parse("2.5")).contains("'2.5'"));
        assert!(s.parse("abc").is_err());
        assert!(s.convert(&Value::Bool(true)).is_err());
        assert!(s.convert(&Value::None).is_err());
        assert_eq!(s.convert(&Value::Float(3.0)).unwrap(), Value::Integer(3));
    }

    #[test]
    fn floats_are_finite_unless_the_range_allows_infinity() {
        let s = schema(Kind::Float, Range::POSITIVE, false);
        assert_eq!(s.parse("1e-6").unwrap(), Value::Float(1e-6));
        assert_eq!(s.convert(&Value::Integer(2)).unwrap(), Value::Float(2.0));
        for bad in ["inf", "nan", "0", "-1", "abc", ""] {
            let r = reason(s.parse(bad));
            assert!(r.contains("a float > 0"), "{bad}: {r}");
        }
        let any = schema(Kind::Float, Range::ANY, false);
        assert!(reason(any.parse("inf")).contains("a finite float"));
        let or_inf = schema(Kind::Float, "(0, inf]".parse().unwrap(), false);
        assert_eq!(or_inf.parse("inf").unwrap(), Value::Float(f64::INFINITY));
    }

    #[test]
    fn optional_values_take_none() {
        let s = schema(Kind::Float, Range::POSITIVE, true);
        assert_eq!(s.parse("none").unwrap(), Value::None);
        assert_eq!(s.parse("None").unwrap(), Value::None);
        assert_eq!(s.convert(&Value::None).unwrap(), Value::None);
        assert!(reason(s.parse("-3")).contains("or none"));
        let required = schema(Kind::Float, Range::POSITIVE, false);
        assert!(required.parse("none").is_err());
        assert_eq!(s.type_name(), "float or none");
    }

    #[test]
    fn choices_are_matched_by_name() {
        let s = schema(Kind::Choice(vec!["QR".into(), "CHOLESKY".into()]), Range::ANY, false);
        assert_eq!(s.parse("QR").unwrap(), Value::Text("QR".into()));
        assert_eq!(s.parse("cholesky").unwrap(), Value::Text("CHOLESKY".into()));
        let r = reason(s.parse("LU"));
        assert!(r.contains("one of QR, CHOLESKY") && r.contains("'LU'"), "{r}");
        assert!(s.convert(&Value::Float(1.0)).is_err());
        assert_eq!(s.type_name(), "QR | CHOLESKY");
    }
}
