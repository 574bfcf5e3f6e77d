//! Parameter tables and the method registry, for Python: conversion
//! between Python values and `params::Value`, and nothing else. Each call
//! crosses once with a whole dict or table (never once per parameter).

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString};

use scattertrack_core::params::{Kind, Range, Schema, Schemas, Value};
use scattertrack_core::track::{registry, Params};

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// A Python value as a parameter value (bool before int: `True` is an int).
fn value_from_py(name: &str, object: &Bound<'_, PyAny>) -> PyResult<Value> {
    if object.is_none() {
        return Ok(Value::None);
    }
    if object.is_instance_of::<PyBool>() {
        return Ok(Value::Bool(object.extract()?));
    }
    if object.is_instance_of::<PyString>() {
        return Ok(Value::Text(object.extract()?));
    }
    if object.is_instance_of::<PyFloat>() {
        return Ok(Value::Float(object.extract()?));
    }
    // Python ints and numpy integers (`__index__`); one too large for i64 is
    // out of every range, so it goes on as a float to be refused by range.
    if object.is_instance_of::<PyInt>() || object.hasattr("__index__")? {
        return Ok(match object.extract::<i64>() {
            Ok(i) => Value::Integer(i),
            Err(_) => Value::Float(object.extract::<f64>()?),
        });
    }
    object.extract::<f64>().map(Value::Float).map_err(|_| {
        let type_name = object.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        value_error(format!("invalid parameter '{name}': expected a number, bool, text or None, got a {type_name}"))
    })
}

fn value_to_py<'py>(py: Python<'py>, value: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        Value::None => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Integer(i) => i.into_pyobject(py)?.into_any(),
        Value::Float(x) => PyFloat::new(py, *x).into_any(),
        Value::Text(s) => PyString::new(py, s).into_any(),
    })
}

/// A dict of name → value as (name, value) pairs, in the dict's order.
fn values_from_dict(params: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, Value)>> {
    let Some(params) = params else { return Ok(Vec::new()) };
    params
        .iter()
        .map(|(key, value)| {
            let name: String = key.extract()?;
            let value = value_from_py(&name, &value)?;
            Ok((name, value))
        })
        .collect()
}

fn values_to_dict<'py>(py: Python<'py>, values: &[(String, Value)]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (name, value) in values {
        d.set_item(name, value_to_py(py, value)?)?;
    }
    Ok(d)
}

fn kind_name(kind: &Kind) -> &'static str {
    match kind {
        Kind::Bool => "bool",
        Kind::Integer => "integer",
        Kind::Float => "float",
        Kind::Choice(_) => "choice",
    }
}

fn schema_to_dict<'py>(py: Python<'py>, s: &Schema) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", &s.name)?;
    d.set_item("type", s.type_name())?;
    d.set_item("kind", kind_name(&s.kind))?;
    d.set_item("optional", s.optional)?;
    let choices = match &s.kind {
        Kind::Choice(c) => Some(c.clone()),
        _ => None,
    };
    d.set_item("choices", choices)?;
    d.set_item("default", value_to_py(py, &s.default)?)?;
    d.set_item("range", s.range_text())?;
    d.set_item("unit", &s.unit)?;
    d.set_item("description", &s.description)?;
    Ok(d)
}

/// A row written in Python: `name`, `kind` (bool | integer | float |
/// choice), `default`, and optionally `optional`, `choices`, `range` (as
/// `Range` writes it: "> 0", "[0, 1]"), `unit`, `description`.
fn schema_from_dict(row: &Bound<'_, PyDict>) -> PyResult<Schema> {
    let item = |key: &str| row.get_item(key);
    let name: String = item("name")?.ok_or_else(|| value_error("a parameter row needs a 'name'"))?.extract()?;
    let text = |key: &str| -> PyResult<String> { Ok(item(key)?.map(|v| v.extract()).transpose()?.unwrap_or_default()) };
    let kind = match text("kind")?.as_str() {
        "bool" => Kind::Bool,
        "integer" => Kind::Integer,
        "float" => Kind::Float,
        "choice" => Kind::Choice(item("choices")?.map(|v| v.extract()).transpose()?.unwrap_or_default()),
        other => return Err(value_error(format!("parameter row '{name}': kind must be bool, integer, float or choice, got {other:?}"))),
    };
    let range: Range = text("range")?.parse().map_err(|e| value_error(format!("parameter row '{name}': {e}")))?;
    let default = match item("default")? {
        Some(v) => value_from_py(&name, &v)?,
        None => Value::None,
    };
    let optional = item("optional")?.map(|v| v.extract()).transpose()?.unwrap_or(false);
    Ok(Schema { kind, optional, range, unit: text("unit")?, description: text("description")?, default, name })
}

/// One method's parameter table: its rows (name, type, default, range,
/// unit, description) and the checks of values given for them.
#[pyclass(module = "scattertrack._core", frozen)]
pub struct ParameterTable {
    inner: Schemas,
}

#[pymethods]
impl ParameterTable {
    /// A table from rows written in Python (see `_core.pyi`); every default
    /// must pass its own row's check.
    #[new]
    fn new(label: &str, rows: Vec<Bound<'_, PyDict>>) -> PyResult<Self> {
        let rows = rows.iter().map(schema_from_dict).collect::<PyResult<Vec<_>>>()?;
        Ok(Self { inner: Schemas::from_rows(label, rows).map_err(value_error)? })
    }

    /// The table of a core method (ValueError for an unknown or Python-side one).
    #[staticmethod]
    fn of_method(method: &str) -> PyResult<Self> {
        Ok(Self { inner: registry::schemas(method).map_err(value_error)? })
    }

    /// Whose parameters these are (a method name).
    #[getter]
    fn label(&self) -> &str {
        &self.inner.label
    }

    /// Every row as a dict, in table order.
    fn rows<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let rows = self.inner.rows.iter().map(|s| schema_to_dict(py, s)).collect::<PyResult<Vec<_>>>()?;
        PyList::new(py, rows)
    }

    /// Every parameter name, in table order.
    fn names(&self) -> Vec<String> {
        self.inner.rows.iter().map(|s| s.name.clone()).collect()
    }

    /// name → default.
    fn defaults<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let values: Vec<(String, Value)> = self.inner.rows.iter().map(|s| (s.name.clone(), s.default.clone())).collect();
        values_to_dict(py, &values)
    }

    /// `params` (name → value) checked and converted to each row's type;
    /// ValueError naming the parameter, what it must be and the value.
    fn check<'py>(&self, py: Python<'py>, params: &Bound<'py, PyDict>) -> PyResult<Bound<'py, PyDict>> {
        let values = self.inner.convert_all(&values_from_dict(Some(params))?).map_err(value_error)?;
        values_to_dict(py, &values)
    }

    /// `(name, text)` pairs (the command line's NAME=TEXT) as typed values.
    fn parse<'py>(&self, py: Python<'py>, pairs: Vec<(String, String)>) -> PyResult<Bound<'py, PyDict>> {
        let values = self.inner.parse_all(&pairs).map_err(value_error)?;
        values_to_dict(py, &values)
    }
}

/// The parameters of core method `method` from a dict of names → values
/// (its table's defaults with these set); errors name the parameter.
pub fn make_params(method: &str, params: Option<&Bound<'_, PyDict>>) -> PyResult<Params> {
    registry::params(method, &values_from_dict(params)?).map_err(value_error)
}

/// Every registered method as a dict: name, pipeline (cots | helper |
/// drone), input (reads | frames | features+imu | sigmf+imu),
/// input_files, estimator (core | python), description.
#[pyfunction]
fn methods(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let rows = registry::METHODS
        .iter()
        .map(|m| {
            let d = PyDict::new(py);
            d.set_item("name", m.name)?;
            d.set_item("pipeline", m.pipeline.as_str())?;
            d.set_item("input", m.input.as_str())?;
            d.set_item("input_files", m.input.describe())?;
            d.set_item("estimator", if m.in_core() { "core" } else { "python" })?;
            d.set_item("description", m.description)?;
            Ok(d)
        })
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, rows)
}

/// Default parameters of core method `method` as a dict (the names `Engine`
/// accepts); ValueError naming the known methods for an unknown one.
#[pyfunction]
#[pyo3(signature = (method="glac"))]
fn default_params<'py>(py: Python<'py>, method: &str) -> PyResult<Bound<'py, PyDict>> {
    ParameterTable::of_method(method)?.defaults(py)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<ParameterTable>()?;
    m.add_function(wrap_pyfunction!(methods, m)?)?;
    m.add_function(wrap_pyfunction!(default_params, m)?)?;
    Ok(())
}
