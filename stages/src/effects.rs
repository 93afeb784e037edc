//! The `effects` parameter of the virtual-printer stages: `name=strength` pairs
//! separated by commas, each domain checking the names and strengths itself; and the
//! power studies' per-effect strength lists.

use pipeline::params::ParamError;

/// Parses `name=strength, name=strength` (empty: none) into pairs.
pub fn pairs(text: &str) -> Result<Vec<(&str, f64)>, String> {
    let mut pairs = Vec::new();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (name, value) = item.split_once('=').ok_or_else(|| format!("effects: `{item}` is not name=strength"))?;
        let strength: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("effects: strength of `{}` is not a number: `{value}`", name.trim()))?;
        pairs.push((name.trim(), strength));
    }
    Ok(pairs)
}

/// The strengths listed in `list`, the text parameter `field` (comma-separated; empty:
/// none), each a magnitude in `(0, top]`; a bad one is a parameter error naming it, with
/// `range_note` after the range. Stages call it in their plan-time check and again when
/// they run.
pub fn strength_list(field: &'static str, list: &str, top: f64, range_note: &str) -> Result<Vec<f64>, ParamError> {
    list.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            let bad = |why: String| ParamError::new(field, format!("`{s}` {why}"));
            let x: f64 = s.parse().map_err(|_| bad("is not a number".into()))?;
            if x > 0.0 && x <= top {
                Ok(x)
            } else {
                Err(bad(format!("is outside (0, {top}]{range_note}")))
            }
        })
        .collect()
}
