//! Figure stage kinds: each reads published tables of its input stages and draws one
//! figure as PNG and SVG, in the style of the paper it reproduces.

mod width_profiles;

pub use width_profiles::WidthProfilesFigure;

use pipeline::Registry;

/// Registers every figure kind.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(WidthProfilesFigure));
}
