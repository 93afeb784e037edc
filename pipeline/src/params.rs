//! Stage parameters: each stage kind declares its parameters (name, type, range,
//! default, doc) once; the planner checks a spec's values against them and fills in
//! defaults, so a stage only ever sees a complete, valid [`Params`].

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

/// The type and admissible range of one parameter.
#[derive(Debug, Clone, Copy)]
pub enum ParamType {
    /// A real number in `[min, max]`.
    Float {
        /// Smallest admissible value.
        min: f64,
        /// Largest admissible value.
        max: f64,
    },
    /// An integer in `[min, max]`.
    Int {
        /// Smallest admissible value.
        min: i64,
        /// Largest admissible value.
        max: i64,
    },
    /// One of a fixed set of strings.
    Choice(&'static [&'static str]),
    /// Any string.
    Text,
    /// True or false.
    Bool,
}

/// A checked parameter value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ParamValue {
    /// A boolean.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A real number.
    Float(f64),
    /// A string.
    Str(String),
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bool(b) => write!(f, "{b}"),
            Self::Int(i) => write!(f, "{i}"),
            Self::Float(x) => write!(f, "{x}"),
            Self::Str(s) => write!(f, "\"{s}\""),
        }
    }
}

/// The declaration of one parameter of a stage kind.
#[derive(Debug, Clone, Copy)]
pub struct ParamSpec {
    /// Name as written in the spec, with its unit (`steady_from_mm`).
    pub name: &'static str,
    /// Type and range.
    pub ty: ParamType,
    /// Value used when the spec does not set it.
    pub default: ParamDefault,
    /// One sentence: what it does, and where its default comes from.
    pub doc: &'static str,
}

/// A parameter default, as a constant so declarations can be `static`.
#[derive(Debug, Clone, Copy)]
pub enum ParamDefault {
    /// No default: the spec must set it.
    Required,
    /// A boolean default.
    Bool(bool),
    /// An integer default.
    Int(i64),
    /// A real default.
    Float(f64),
    /// A string default.
    Str(&'static str),
}

impl ParamDefault {
    fn value(self) -> Option<ParamValue> {
        match self {
            Self::Required => None,
            Self::Bool(b) => Some(ParamValue::Bool(b)),
            Self::Int(i) => Some(ParamValue::Int(i)),
            Self::Float(x) => Some(ParamValue::Float(x)),
            Self::Str(s) => Some(ParamValue::Str(s.to_string())),
        }
    }
}

impl fmt::Display for ParamDefault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.value() {
            None => write!(f, "(required)"),
            Some(v) => write!(f, "{v}"),
        }
    }
}

impl fmt::Display for ParamType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Float { min, max } => write!(f, "number in [{min}, {max}]"),
            Self::Int { min, max } => write!(f, "integer in [{min}, {max}]"),
            Self::Choice(c) => write!(f, "one of {}", c.join(", ")),
            Self::Text => write!(f, "string"),
            Self::Bool => write!(f, "true or false"),
        }
    }
}

/// A complete, checked parameter set of one stage: every declared parameter present.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Params(BTreeMap<String, ParamValue>);

impl Params {
    /// Checks raw spec values against the declarations: unknown names, wrong types and
    /// out-of-range values are errors `(field, message)`; missing ones get defaults.
    pub fn check(decls: &[ParamSpec], raw: &BTreeMap<String, toml::Value>) -> Result<Self, (String, String)> {
        if let Some(unknown) = raw.keys().find(|k| !decls.iter().any(|d| d.name == *k)) {
            let known: Vec<&str> = decls.iter().map(|d| d.name).collect();
            return Err((unknown.clone(), format!("unknown parameter; this kind takes: {}", known.join(", "))));
        }
        let mut values = BTreeMap::new();
        for decl in decls {
            let value = match raw.get(decl.name) {
                Some(v) => check_value(decl, v).map_err(|m| (decl.name.to_string(), m))?,
                None => {
                    decl.default.value().ok_or_else(|| (decl.name.to_string(), format!("required: {}", decl.ty)))?
                }
            };
            values.insert(decl.name.to_string(), value);
        }
        Ok(Self(values))
    }

    /// All values by name, sorted (the order hashed for the cache).
    pub fn iter(&self) -> impl Iterator<Item = (&String, &ParamValue)> {
        self.0.iter()
    }

    /// A real-valued parameter (integers are widened).
    pub fn f64(&self, name: &str) -> f64 {
        match self.get(name) {
            ParamValue::Float(x) => *x,
            ParamValue::Int(i) => *i as f64,
            other => panic!("parameter `{name}` is {other}, not a number: declaration bug"),
        }
    }

    /// An integer parameter.
    pub fn i64(&self, name: &str) -> i64 {
        match self.get(name) {
            ParamValue::Int(i) => *i,
            other => panic!("parameter `{name}` is {other}, not an integer: declaration bug"),
        }
    }

    /// A string or choice parameter.
    pub fn str(&self, name: &str) -> &str {
        match self.get(name) {
            ParamValue::Str(s) => s,
            other => panic!("parameter `{name}` is {other}, not a string: declaration bug"),
        }
    }

    /// A boolean parameter.
    pub fn bool(&self, name: &str) -> bool {
        match self.get(name) {
            ParamValue::Bool(b) => *b,
            other => panic!("parameter `{name}` is {other}, not a boolean: declaration bug"),
        }
    }

    fn get(&self, name: &str) -> &ParamValue {
        self.0.get(name).unwrap_or_else(|| panic!("parameter `{name}` is not declared by this kind"))
    }
}

fn check_value(decl: &ParamSpec, raw: &toml::Value) -> Result<ParamValue, String> {
    let expected = || format!("expected {}, got {raw}", decl.ty);
    match (decl.ty, raw) {
        (ParamType::Float { min, max }, toml::Value::Float(x)) => in_range(*x, min, max, expected),
        (ParamType::Float { min, max }, toml::Value::Integer(i)) => in_range(*i as f64, min, max, expected),
        (ParamType::Int { min, max }, toml::Value::Integer(i)) if (min..=max).contains(i) => Ok(ParamValue::Int(*i)),
        (ParamType::Choice(choices), toml::Value::String(s)) if choices.contains(&s.as_str()) => {
            Ok(ParamValue::Str(s.clone()))
        }
        (ParamType::Text, toml::Value::String(s)) => Ok(ParamValue::Str(s.clone())),
        (ParamType::Bool, toml::Value::Boolean(b)) => Ok(ParamValue::Bool(*b)),
        _ => Err(expected()),
    }
}

fn in_range(x: f64, min: f64, max: f64, expected: impl Fn() -> String) -> Result<ParamValue, String> {
    if x.is_finite() && x >= min && x <= max {
        Ok(ParamValue::Float(x))
    } else {
        Err(expected())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DECLS: &[ParamSpec] = &[
        ParamSpec {
            name: "from_mm",
            ty: ParamType::Float { min: 0.0, max: 120.0 },
            default: ParamDefault::Float(50.0),
            doc: "start",
        },
        ParamSpec {
            name: "edge",
            ty: ParamType::Choice(&["half_max", "otsu"]),
            default: ParamDefault::Required,
            doc: "edge rule",
        },
    ];

    fn raw(src: &str) -> BTreeMap<String, toml::Value> {
        toml::from_str(src).unwrap()
    }

    #[test]
    fn fills_defaults_and_widens_integers() {
        let p = Params::check(DECLS, &raw("edge = \"otsu\"\nfrom_mm = 60")).unwrap();
        assert_eq!(p.f64("from_mm"), 60.0);
        assert_eq!(p.str("edge"), "otsu");
        let p = Params::check(DECLS, &raw("edge = \"otsu\"")).unwrap();
        assert_eq!(p.f64("from_mm"), 50.0);
    }

    #[test]
    fn rejects_unknown_missing_ill_typed_and_out_of_range() {
        let err = |src| Params::check(DECLS, &raw(src)).unwrap_err();
        assert_eq!(err("edge = \"otsu\"\nfrm_mm = 1").0, "frm_mm");
        assert_eq!(err("from_mm = 1.0").0, "edge");
        assert!(err("edge = 3").1.contains("one of half_max, otsu"));
        assert!(err("edge = \"otsu\"\nfrom_mm = -1.0").1.contains("[0, 120]"));
        assert!(err("edge = \"otsu\"\nfrom_mm = \"x\"").1.contains("number"));
    }
}
