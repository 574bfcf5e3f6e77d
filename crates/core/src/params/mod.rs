//! Typed tracker parameters: one table per parameter struct, the only
//! place a parameter's name, type, range, unit and description are written.
//!
//! A table is a list of rows ([`Parameter`]): a [`Schema`] plus how to
//! read and write the field. The default is read from the struct's
//! `Default` through the row's getter, so the defaults stay where they
//! always were (`impl Default for GlacParams`) and cannot drift from the
//! docs. The bindings, the CLI and the generated `docs/parameters.md` read
//! [`Table::schemas`]; [`Table::build`] sets parameters by name from typed
//! values, [`Table::set_text`] from text.
//!
//! Adding a parameter: the field and its default in the struct, one row in
//! the struct's table (`track/glac_params.rs`, `track/turbotrack_params.rs`).

mod range;
mod schema;
mod suggest;

pub use range::{format_number, Bound, Range};
pub use schema::{Kind, Schema, Value, FALSE_WORDS, TRUE_WORDS};
pub use suggest::close_matches;

use crate::error::{Error, Result};

type Getter<P> = Box<dyn Fn(&P) -> Value + Send + Sync>;
/// Writes a value already converted by the row's schema; the `Err` is the
/// reason (only reachable when a row's kind and setter disagree).
type Setter<P> = Box<dyn Fn(&mut P, &Value) -> std::result::Result<(), String> + Send + Sync>;

/// One row of a table over the parameter struct `P`.
pub struct Parameter<P> {
    /// Everything but the default (read from `P::default()` by `get`).
    pub schema: Schema,
    get: Getter<P>,
    set: Setter<P>,
}

#[allow(clippy::too_many_arguments)] // one per column of a table row
fn row<P>(name: &str, kind: Kind, optional: bool, range: Range, unit: &str, description: &str, get: Getter<P>, set: Setter<P>) -> Parameter<P> {
    let schema = Schema {
        name: name.to_string(),
        kind,
        optional,
        range,
        unit: unit.to_string(),
        description: description.to_string(),
        default: Value::None,
    };
    Parameter { schema, get, set }
}

fn mismatch(value: &Value) -> String {
    format!("internal: the row's setter cannot take {value}")
}

/// A float field (finite unless `range` allows infinity).
pub fn float<P: 'static>(name: &str, range: Range, unit: &str, description: &str, get: fn(&P) -> f64, set: fn(&mut P, f64)) -> Parameter<P> {
    row(
        name,
        Kind::Float,
        false,
        range,
        unit,
        description,
        Box::new(move |p| Value::Float(get(p))),
        Box::new(move |p, v| match v {
            Value::Float(x) => {
                set(p, *x);
                Ok(())
            }
            other => Err(mismatch(other)),
        }),
    )
}

/// An `Option<f64>` field: `none` switches the feature off.
pub fn optional_float<P: 'static>(
    name: &str,
    range: Range,
    unit: &str,
    description: &str,
    get: fn(&P) -> Option<f64>,
    set: fn(&mut P, Option<f64>),
) -> Parameter<P> {
    row(
        name,
        Kind::Float,
        true,
        range,
        unit,
        description,
        Box::new(move |p| get(p).map_or(Value::None, Value::Float)),
        Box::new(move |p, v| match v {
            Value::Float(x) => {
                set(p, Some(*x));
                Ok(())
            }
            Value::None => {
                set(p, None);
                Ok(())
            }
            other => Err(mismatch(other)),
        }),
    )
}

/// An integer field of any integer type `T`; an unsigned `T` raises the
/// range's floor to 0, so negatives are refused with the range shown.
pub fn integer<P: 'static, T>(name: &str, range: Range, unit: &str, description: &str, get: fn(&P) -> T, set: fn(&mut P, T)) -> Parameter<P>
where
    T: TryFrom<i64> + TryInto<i64> + Copy + 'static,
{
    let range = if T::try_from(-1).is_err() { range.with_floor(0.0) } else { range };
    row(
        name,
        Kind::Integer,
        false,
        range,
        unit,
        description,
        Box::new(move |p| Value::Integer(get(p).try_into().unwrap_or(i64::MAX))),
        Box::new(move |p, v| match v {
            Value::Integer(i) => T::try_from(*i).map(|t| set(p, t)).map_err(|_| format!("{i} does not fit the field's type")),
            other => Err(mismatch(other)),
        }),
    )
}

/// A bool field.
pub fn boolean<P: 'static>(name: &str, description: &str, get: fn(&P) -> bool, set: fn(&mut P, bool)) -> Parameter<P> {
    row(
        name,
        Kind::Bool,
        false,
        Range::ANY,
        "",
        description,
        Box::new(move |p| Value::Bool(get(p))),
        Box::new(move |p, v| match v {
            Value::Bool(b) => {
                set(p, *b);
                Ok(())
            }
            other => Err(mismatch(other)),
        }),
    )
}

/// A field of an enum-like type `T`, one name per variant: `choices` is
/// the one list of (name, variant), read both ways.
pub fn choice<P: 'static, T>(name: &str, description: &str, choices: &'static [(&'static str, T)], get: fn(&P) -> T, set: fn(&mut P, T)) -> Parameter<P>
where
    T: Copy + PartialEq + Send + Sync + 'static,
{
    let names = choices.iter().map(|(n, _)| n.to_string()).collect();
    row(
        name,
        Kind::Choice(names),
        false,
        Range::ANY,
        "",
        description,
        Box::new(move |p| {
            let current = get(p);
            choices.iter().find(|(_, t)| *t == current).map_or(Value::None, |(n, _)| Value::Text(n.to_string()))
        }),
        Box::new(move |p, v| match v {
            Value::Text(text) => match choices.iter().find(|(n, _)| n == text) {
                Some((_, t)) => {
                set(p, *t);
                Ok(())
            }
                None => Err(mismatch(v)),
            },
            other => Err(mismatch(other)),
        }),
    )
}

/// A table: the parameters of one parameter struct `P`.
pub struct Table<P> {
    /// Who the parameters belong to in messages: a method name.
    pub label: String,
    rows: Vec<Parameter<P>>,
}

impl<P: Default> Table<P> {
    pub fn new(label: &str, rows: Vec<Parameter<P>>) -> Self {
        Self { label: label.to_string(), rows }
    }

    /// The same table, its messages naming `label` (the method asked for).
    pub fn labelled(mut self, label: &str) -> Self {
        self.label = label.to_string();
        self
    }

    fn find(&self, name: &str) -> Result<&Parameter<P>> {
        self.rows.iter().find(|r| r.schema.name == name).ok_or_else(|| {
            unknown_parameter(&self.label, name, self.rows.iter().map(|r| r.schema.name.as_str()))
        })
    }

    /// The rows with their defaults (read from `P::default()`).
    pub fn schemas(&self) -> Schemas {
        let defaults = P::default();
        let rows = self.rows.iter().map(|r| Schema { default: (r.get)(&defaults), ..r.schema.clone() }).collect();
        Schemas { label: self.label.clone(), rows }
    }

    /// The current value of parameter `name` in `params`.
    pub fn get(&self, params: &P, name: &str) -> Result<Value> {
        Ok((self.find(name)?.get)(params))
    }

    /// Sets parameter `name` from a typed value (converted and checked by its schema).
    pub fn set(&self, params: &mut P, name: &str, value: &Value) -> Result<()> {
        let row = self.find(name)?;
        let value = row.schema.convert(value)?;
        (row.set)(params, &value).map_err(|reason| Error::Parameter { name: name.to_string(), reason })
    }

    /// Sets parameter `name` from text (the command line's `NAME=TEXT`).
    pub fn set_text(&self, params: &mut P, name: &str, text: &str) -> Result<()> {
        let value = self.find(name)?.schema.parse(text)?;
        self.set(params, name, &value)
    }

    /// The defaults with `values` (name → value) set in order.
    pub fn build(&self, values: &[(String, Value)]) -> Result<P> {
        let mut params = P::default();
        for (name, value) in values {
            self.set(&mut params, name, value)?;
        }
        Ok(params)
    }
}

/// The unknown-name error of a table labelled `label`, with close matches.
fn unknown_parameter<'a>(label: &str, name: &str, known: impl Iterator<Item = &'a str>) -> Error {
    let known: Vec<String> = known.map(str::to_string).collect();
    Error::UnknownParameter {
        name: name.to_string(),
        method: label.to_string(),
        close: close_matches(name, known.iter().map(String::as_str)),
        known,
    }
}

/// A table without access to any struct (what [`Table::schemas`] returns,
/// or rows given from outside Rust): it checks and converts values by name.
#[derive(Debug, Clone, PartialEq)]
pub struct Schemas {
    pub label: String,
    pub rows: Vec<Schema>,
}

impl Schemas {
    /// A table from rows written elsewhere (Marvel's, in Python): names
    /// must be unique and every default must pass its own row's check.
    pub fn from_rows(label: &str, rows: Vec<Schema>) -> Result<Self> {
        for (i, row) in rows.iter().enumerate() {
            if rows[..i].iter().any(|r| r.name == row.name) {
                return Err(Error::Parameter { name: row.name.clone(), reason: "appears twice in the table".into() });
            }
            row.convert(&row.default).map_err(|e| Error::Parameter {
                name: row.name.clone(),
                reason: format!("the table's default is not allowed: {e}"),
            })?;
        }
        Ok(Self { label: label.to_string(), rows })
    }

    /// The row of parameter `name`.
    pub fn find(&self, name: &str) -> Result<&Schema> {
        self.rows
            .iter()
            .find(|r| r.name == name)
            .ok_or_else(|| unknown_parameter(&self.label, name, self.rows.iter().map(|r| r.name.as_str())))
    }

    /// `values` checked and converted, in order.
    pub fn convert_all(&self, values: &[(String, Value)]) -> Result<Vec<(String, Value)>> {
        values.iter().map(|(n, v)| Ok((n.clone(), self.find(n)?.convert(v)?))).collect()
    }

    /// `NAME=TEXT` pairs read into typed values, in order.
    pub fn parse_all(&self, pairs: &[(String, String)]) -> Result<Vec<(String, Value)>> {
        pairs.iter().map(|(n, t)| Ok((n.clone(), self.find(n)?.parse(t)?))).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Mode {
        Fast,
        Slow,
    }

    #[derive(Debug, Clone, PartialEq)]
    struct Example {
        gain: f64,
        count: usize,
        offset: i32,
        cap: Option<f64>,
        on: bool,
        mode: Mode,
    }

    impl Default for Example {
        fn default() -> Self {
            Self { gain: 0.5, count: 3, offset: -2, cap: None, on: true, mode: Mode::Fast }
        }
    }

    fn table() -> Table<Example> {
        Table::new(
            "example",
            vec![
                float("gain", Range::UNIT, "", "a fraction", |p| p.gain, |p, v| p.gain = v),
                integer("count", Range::at_least(1.0), "", "how many", |p| p.count, |p, v| p.count = v),
                integer("offset", Range::ANY, "", "signed", |p| p.offset, |p, v| p.offset = v),
                optional_float("cap", Range::POSITIVE, "m", "a cap", |p| p.cap, |p, v| p.cap = v),
                boolean("on", "a switch", |p| p.on, |p, v| p.on = v),
                choice("mode", "a mode", &[("fast", Mode::Fast), ("slow", Mode::Slow)], |p| p.mode, |p, v| p.mode = v),
            ],
        )
    }

    #[test]
    fn defaults_come_from_the_struct() {
        let s = table().schemas();
        let default = |n: &str| s.find(n).unwrap().default.clone();
        assert_eq!(default("gain"), Value::Float(0.5));
        assert_eq!(default("count"), Value::Integer(3));
        assert_eq!(default("cap"), Value::None);
        assert_eq!(default("mode"), Value::Text("fast".into()));
    }

    #[test]
    fn values_are_set_by_name() {
        let t = table();
        let p = t
            .build(&[
                ("gain".into(), Value::Integer(1)),
                ("count".into(), Value::Text("7".into())),
                ("cap".into(), Value::Float(2.0)),
                ("on".into(), Value::Text("no".into())),
                ("mode".into(), Value::Text("slow".into())),
                ("offset".into(), Value::Integer(-5)),
            ])
            .unwrap();
        assert_eq!(p, Example { gain: 1.0, count: 7, offset: -5, cap: Some(2.0), on: false, mode: Mode::Slow });
        let mut q = p.clone();
        t.set_text(&mut q, "cap", "none").unwrap();
        assert_eq!(q.cap, None);
        assert_eq!(t.get(&q, "mode").unwrap(), Value::Text("slow".into()));
    }

    #[test]
    fn unsigned_fields_refuse_negatives() {
        let t = table();
        assert_eq!(t.schemas().find("count").unwrap().range, Range::at_least(1.0));
        match t.build(&[("count".into(), Value::Integer(-1))]) {
            Err(Error::Parameter { name, reason }) => assert!(name == "count" && reason.contains(">= 1") && reason.contains("-1")),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn unknown_names_list_close_matches() {
        let message = table().build(&[("gian".into(), Value::Float(0.1))]).unwrap_err().to_string();
        assert!(message.contains("unknown parameter 'gian' for method 'example'") && message.contains("gain"), "{message}");
        let message = table().labelled("other").build(&[("zzzzzz".into(), Value::Float(0.1))]).unwrap_err().to_string();
        assert!(message.contains("'other'") && message.contains("known: gain, count"), "{message}");
    }

    #[test]
    fn rows_from_outside_are_checked() {
        let mut rows = table().schemas().rows;
        assert!(Schemas::from_rows("x", rows.clone()).is_ok());
        rows[0].default = Value::Float(2.0);
        assert!(Schemas::from_rows("x", rows.clone()).unwrap_err().to_string().contains("'gain'"));
        rows[0] = rows[1].clone();
        assert!(Schemas::from_rows("x", rows).unwrap_err().to_string().contains("twice"));
    }
}
