//! Input roles that several stage kinds share: what each reads from the dataset or
//! upstream stage a spec wires to it. A kind's own roles are declared beside it.

use pipeline::stage::{Input, Source};

/// One printer's measured line widths.
pub const FDM_WIDTHS: Input =
    Input::one("widths", &[Source::Dataset("fdm-widths")], "one printer's measured line widths (`fdm-widths`)");

/// Several printers' measured line widths.
pub const FDM_WIDTHS_MANY: Input = Input::many(
    "widths",
    1,
    &[Source::Dataset("fdm-widths")],
    "measured line widths, one `fdm-widths` dataset per printer",
);

/// Photos of printed lines.
pub const FDM_LINES_MANY: Input =
    Input::many("photos", 1, &[Source::Dataset("fdm-lines")], "photos of printed lines, one `fdm-lines` dataset each");

/// A sequence of thermal frames.
pub const THERMAL_SEQUENCE: Input =
    Input::one("sequence", &[Source::Dataset("thermal-sequence")], "a filmed print (`thermal-sequence`)");

/// Ink-jet height scans.
pub const INKJET_SCANS: Input =
    Input::one("scans", &[Source::Dataset("inkjet-scans")], "layer-by-layer height scans (`inkjet-scans`)");
