//! The `effects` parameter of the virtual-printer stages: `name=strength` pairs
//! separated by commas, each domain checking the names and strengths itself.

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
