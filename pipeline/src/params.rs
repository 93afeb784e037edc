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

impl ParamSpec {
    /// Whether the declared default is admissible for the declared type and range (a
    /// required parameter has none to check).
    pub fn check_default(&self) -> Result<(), String> {
        let raw = match self.default.value() {
            None => return Ok(()),
            Some(ParamValue::Bool(b)) => toml::Value::Boolean(b),
            Some(ParamValue::Int(i)) => toml::Value::Integer(i),
            Some(ParamValue::Float(x)) => toml::Value::Float(x),
            Some(ParamValue::Str(s)) => toml::Value::String(s),
        };
        check_value(self, &raw).map(|_| ())
    }
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

/// A parameter the cross-field check of a stage kind refused: the field it names and why.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamError {
    /// The parameter (as written in the spec) the message is about.
    pub field: &'static str,
    /// What is wrong and what was expected.
    pub message: String,
}

impl ParamError {
    /// `field` is wrong: `message`.
    pub fn new(field: &'static str, message: impl Into<String>) -> Self {
        Self { field, message: message.into() }
    }
}

/// A stage's parameters as one typed struct, declared once with [`crate::params!`]: the
/// declarations the planner checks a spec against ([`StageParams::specs`]) and the
/// struct built from the checked values ([`StageParams::from_params`]) come from the same
/// field list, so a parameter read under a misspelled name does not compile.
pub trait StageParams: Sized + Send + Sync + 'static {
    /// The declarations, in field order (groups after the fields).
    fn specs() -> &'static [ParamSpec];
    /// The struct from values checked against [`StageParams::specs`].
    fn from_params(params: &Params) -> Self;
    /// The struct with every parameter at its declared default; `None` when one is
    /// required.
    fn defaults() -> Option<Self> {
        Params::check(Self::specs(), &BTreeMap::new()).ok().map(|p| Self::from_params(&p))
    }
}

/// No parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NoParams;

impl StageParams for NoParams {
    fn specs() -> &'static [ParamSpec] {
        &[]
    }
    fn from_params(_: &Params) -> Self {
        Self
    }
}

/// A type a parameter field can have: its [`ParamType`], its default as declared and its
/// value from a checked [`ParamValue`].
pub trait ParamField: Sized {
    /// The type of its range bounds (`()` when it has none).
    type Bound;
    /// The type its default is written in (`&'static str` for a string).
    type Default;
    /// The declared type from an optional `[lo, hi]` range.
    fn param_type(range: Option<(Self::Bound, Self::Bound)>) -> ParamType;
    /// The declared default.
    fn declared_default(default: Self::Default) -> ParamDefault;
    /// The value checked against [`ParamField::param_type`].
    fn from_value(value: &ParamValue) -> Option<Self>;
}

impl ParamField for f64 {
    type Bound = f64;
    type Default = f64;
    fn param_type(range: Option<(f64, f64)>) -> ParamType {
        let (min, max) = range.unwrap_or((f64::MIN, f64::MAX));
        ParamType::Float { min, max }
    }
    fn declared_default(default: f64) -> ParamDefault {
        ParamDefault::Float(default)
    }
    fn from_value(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Float(x) => Some(*x),
            ParamValue::Int(i) => Some(*i as f64),
            _ => None,
        }
    }
}

impl ParamField for i64 {
    type Bound = i64;
    type Default = i64;
    fn param_type(range: Option<(i64, i64)>) -> ParamType {
        let (min, max) = range.unwrap_or((i64::MIN, i64::MAX));
        ParamType::Int { min, max }
    }
    fn declared_default(default: i64) -> ParamDefault {
        ParamDefault::Int(default)
    }
    fn from_value(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Int(i) => Some(*i),
            _ => None,
        }
    }
}

/// A count or size: an integer parameter whose range starts at 0 or above.
impl ParamField for usize {
    type Bound = usize;
    type Default = usize;
    fn param_type(range: Option<(usize, usize)>) -> ParamType {
        let (min, max) = range.unwrap_or((0, i64::MAX as usize));
        ParamType::Int { min: min as i64, max: max.min(i64::MAX as usize) as i64 }
    }
    fn declared_default(default: usize) -> ParamDefault {
        ParamDefault::Int(default as i64)
    }
    fn from_value(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Int(i) => usize::try_from(*i).ok(),
            _ => None,
        }
    }
}

/// A seed or other non-negative integer that may exceed `usize` on small targets.
impl ParamField for u64 {
    type Bound = u64;
    type Default = u64;
    fn param_type(range: Option<(u64, u64)>) -> ParamType {
        let (min, max) = range.unwrap_or((0, i64::MAX as u64));
        ParamType::Int { min: min as i64, max: max.min(i64::MAX as u64) as i64 }
    }
    fn declared_default(default: u64) -> ParamDefault {
        ParamDefault::Int(default as i64)
    }
    fn from_value(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Int(i) => u64::try_from(*i).ok(),
            _ => None,
        }
    }
}

impl ParamField for bool {
    type Bound = ();
    type Default = bool;
    fn param_type(_: Option<((), ())>) -> ParamType {
        ParamType::Bool
    }
    fn declared_default(default: bool) -> ParamDefault {
        ParamDefault::Bool(default)
    }
    fn from_value(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Bool(b) => Some(*b),
            _ => None,
        }
    }
}

impl ParamField for String {
    type Bound = ();
    type Default = &'static str;
    fn param_type(_: Option<((), ())>) -> ParamType {
        ParamType::Text
    }
    fn declared_default(default: &'static str) -> ParamDefault {
        ParamDefault::Str(default)
    }
    fn from_value(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Str(s) => Some(s.clone()),
            _ => None,
        }
    }
}

/// A list of names a [`OneOf`] parameter may take, declared where the names live (a
/// model's printer profiles, say) so that the parameter does not copy them.
pub trait Names: Send + Sync + 'static {
    /// The admissible names.
    const NAMES: &'static [&'static str];
}

/// A choice parameter whose admissible names are another module's list ([`Names`]):
/// the name as written in the spec, checked against the list by the planner.
pub struct OneOf<N: Names> {
    name: String,
    names: std::marker::PhantomData<N>,
}

// By hand: derived impls would ask the marker `N` for the same traits.
impl<N: Names> fmt::Debug for OneOf<N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.name)
    }
}

impl<N: Names> Clone for OneOf<N> {
    fn clone(&self) -> Self {
        Self { name: self.name.clone(), names: std::marker::PhantomData }
    }
}

impl<N: Names> PartialEq for OneOf<N> {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
    }
}

impl<N: Names> OneOf<N> {
    /// The chosen name (one of `N::NAMES`).
    pub fn as_str(&self) -> &str {
        &self.name
    }
}

impl<N: Names> ParamField for OneOf<N> {
    type Bound = ();
    type Default = &'static str;
    fn param_type(_: Option<((), ())>) -> ParamType {
        ParamType::Choice(N::NAMES)
    }
    fn declared_default(default: &'static str) -> ParamDefault {
        ParamDefault::Str(default)
    }
    fn from_value(value: &ParamValue) -> Option<Self> {
        match value {
            ParamValue::Str(s) if N::NAMES.contains(&s.as_str()) => {
                Some(Self { name: s.clone(), names: std::marker::PhantomData })
            }
            _ => None,
        }
    }
}

/// The parameter `field` of a checked set as its declared type; used by the code
/// [`crate::params!`] generates, where the name and the type come from one declaration.
///
/// # Panics
/// When `params` were not checked against the declaration that names `field`: a bug in
/// the engine, never a spec error.
#[doc(hidden)]
pub fn checked_field<T: ParamField>(params: &Params, field: &str) -> T {
    params
        .0
        .get(field)
        .and_then(T::from_value)
        .unwrap_or_else(|| panic!("parameter `{field}` missing or of another type in a checked set: an engine bug"))
}

/// Declares a stage's parameters once, as a typed struct: each field's name (with its
/// unit) is the name in the spec, its doc comment the documentation, its type the
/// parameter type (`f64`, `i64`, `usize`, `u64`, `bool`, `String` or a [`crate::choice!`]
/// enum), `[lo, hi]` its range and `= value` its default (none: the spec must set it).
/// A `groups { .. }` block appends parameter structs shared between kinds, flat in the
/// spec.
///
/// ```
/// pipeline::params! {
///     /// Parameters of a smoothing step.
///     pub struct Smoothing {
///         /// Window length along the path (mm).
///         pub window_mm: f64 [0.0, 10.0] = 1.0,
///         /// Whether to also smooth the ends.
///         pub ends: bool,
///     }
/// }
/// # use pipeline::params::StageParams;
/// assert_eq!(Smoothing::specs()[0].name, "window_mm");
/// ```
#[macro_export]
macro_rules! params {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $(
                $(#[doc = $doc:literal])*
                $fvis:vis $field:ident : $ty:ty $([$lo:expr, $hi:expr])? $(= $default:expr)?
            ),* $(,)?
        }
        $(groups { $( $(#[doc = $gdoc:literal])* $gvis:vis $group:ident : $gty:ty ),* $(,)? })?
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq)]
        $vis struct $name {
            $( $(#[doc = $doc])* $fvis $field: $ty, )*
            $($( $(#[doc = $gdoc])* $gvis $group: $gty, )*)?
        }

        impl $crate::params::StageParams for $name {
            fn specs() -> &'static [$crate::params::ParamSpec] {
                static SPECS: ::std::sync::OnceLock<::std::vec::Vec<$crate::params::ParamSpec>> =
                    ::std::sync::OnceLock::new();
                SPECS.get_or_init(|| {
                    #[allow(unused_mut)]
                    let mut specs = ::std::vec![$(
                        $crate::params::ParamSpec {
                            name: stringify!($field),
                            ty: <$ty as $crate::params::ParamField>::param_type(
                                ::std::option::Option::None $(.or(::std::option::Option::Some(($lo, $hi))))?,
                            ),
                            default: ::std::option::Option::None
                                $(.or(::std::option::Option::Some($default)))?
                                .map_or($crate::params::ParamDefault::Required, <$ty as $crate::params::ParamField>::declared_default),
                            doc: concat!($($doc),*).trim_ascii(),
                        },
                    )*];
                    $($( specs.extend_from_slice(<$gty as $crate::params::StageParams>::specs()); )*)?
                    specs
                })
            }

            fn from_params(params: &$crate::params::Params) -> Self {
                Self {
                    $( $field: $crate::params::checked_field::<$ty>(params, stringify!($field)), )*
                    $($( $group: <$gty as $crate::params::StageParams>::from_params(params), )*)?
                }
            }
        }
    };
}

/// Declares a choice parameter's type: an enum whose variants are written in the spec
/// as the given strings.
///
/// ```
/// pipeline::choice! {
///     /// How widths are read.
///     pub enum Edge { HalfMax = "half_max", Otsu = "otsu" }
/// }
/// assert_eq!(Edge::parse("otsu"), Some(Edge::Otsu));
/// assert_eq!(Edge::HalfMax.name(), "half_max");
/// ```
#[macro_export]
macro_rules! choice {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident { $( $(#[doc = $doc:literal])* $variant:ident = $text:literal ),+ $(,)? }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        $vis enum $name { $( $(#[doc = $doc])* $variant, )+ }

        impl $name {
            /// Every variant as written in a spec.
            $vis const NAMES: &'static [&'static str] = &[$($text),+];
            /// Every variant.
            $vis const ALL: &'static [Self] = &[$(Self::$variant),+];
            /// The variant as written in a spec.
            $vis const fn name(self) -> &'static str {
                match self { $(Self::$variant => $text,)+ }
            }
            /// The variant written `text`, if any.
            $vis fn parse(text: &str) -> ::std::option::Option<Self> {
                match text { $($text => ::std::option::Option::Some(Self::$variant),)+ _ => ::std::option::Option::None }
            }
        }

        impl ::std::fmt::Display for $name {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl $crate::params::ParamField for $name {
            type Bound = ();
            type Default = Self;
            fn param_type(_: ::std::option::Option<((), ())>) -> $crate::params::ParamType {
                $crate::params::ParamType::Choice(Self::NAMES)
            }
            fn declared_default(default: Self) -> $crate::params::ParamDefault {
                $crate::params::ParamDefault::Str(default.name())
            }
            fn from_value(value: &$crate::params::ParamValue) -> ::std::option::Option<Self> {
                match value {
                    $crate::params::ParamValue::Str(s) => Self::parse(s),
                    _ => ::std::option::Option::None,
                }
            }
        }
    };
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
        assert_eq!(checked_field::<f64>(&p, "from_mm"), 60.0);
        assert_eq!(checked_field::<String>(&p, "edge"), "otsu");
        let p = Params::check(DECLS, &raw("edge = \"otsu\"")).unwrap();
        assert_eq!(checked_field::<f64>(&p, "from_mm"), 50.0);
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

    crate::choice! {
        /// Edge rules.
        enum Edge {
            /// Half maximum.
            HalfMax = "half_max",
            /// Otsu.
            Otsu = "otsu",
        }
    }

    struct Shades;

    impl Names for Shades {
        const NAMES: &'static [&'static str] = &["light", "dark"];
    }

    crate::params! {
        /// A group.
        struct Shared {
            /// Draws.
            draws: usize [1, 100] = 20,
        }
    }

    crate::params! {
        /// Typed parameters.
        struct Typed {
            /// Start of the window
            /// (mm).
            from_mm: f64 [0.0, 120.0] = 50.0,
            /// Edge rule.
            edge: Edge,
            /// Shade.
            shade: OneOf<Shades> = "dark",
            /// Label.
            label: String = "",
        }
        groups { shared: Shared }
    }

    #[test]
    fn a_declared_struct_gives_its_specs_in_field_order_and_is_built_from_checked_values() {
        let names: Vec<&str> = Typed::specs().iter().map(|p| p.name).collect();
        assert_eq!(names, ["from_mm", "edge", "shade", "label", "draws"], "groups after the fields");
        let from = &Typed::specs()[0];
        assert_eq!(from.doc, "Start of the window (mm).", "doc lines joined");
        assert!(matches!(from.ty, ParamType::Float { min, max } if min == 0.0 && max == 120.0));
        assert!(matches!(Typed::specs()[1].default, ParamDefault::Required));
        assert!(matches!(Typed::specs()[1].ty, ParamType::Choice(c) if c == ["half_max", "otsu"]));
        assert!(matches!(Typed::specs()[2].ty, ParamType::Choice(c) if c == ["light", "dark"]));
        assert!(matches!(Typed::specs()[4].ty, ParamType::Int { min: 1, max: 100 }));
        let checked = Params::check(Typed::specs(), &raw("edge = \"otsu\"\nfrom_mm = 60\ndraws = 7")).unwrap();
        let typed = Typed::from_params(&checked);
        assert_eq!((typed.from_mm, typed.edge, typed.shade.as_str()), (60.0, Edge::Otsu, "dark"));
        assert_eq!((typed.label.as_str(), typed.shared.draws), ("", 7));
        assert!(Typed::defaults().is_none(), "edge is required");
        assert_eq!(Shared::defaults(), Some(Shared { draws: 20 }));
    }

    #[test]
    fn choices_round_trip_and_defaults_are_checked_against_their_declaration() {
        assert!(Edge::ALL.iter().all(|e| Edge::parse(e.name()) == Some(*e)));
        assert_eq!(Edge::parse("median"), None);
        assert_eq!(Edge::Otsu.to_string(), "otsu");
        assert!(Typed::specs().iter().all(|p| p.check_default().is_ok()));
        let bad = ParamSpec {
            name: "x_mm",
            ty: ParamType::Float { min: 0.0, max: 1.0 },
            default: ParamDefault::Float(2.0),
            doc: "",
        };
        assert!(bad.check_default().unwrap_err().contains("[0, 1]"));
    }
}
