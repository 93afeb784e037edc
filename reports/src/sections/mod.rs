//! Report-section stage kinds: each reads published tables of one paper's run and
//! writes `section.html` (embedded in the report) and `comparison.parquet` (paper's
//! number beside ours, with where ours came from).

mod chen2024;
mod chen2024_variants;
mod discrepancy_fdm;
mod discrepancy_inkjet;
mod discrepancy_thermal;
mod fdm_virtual;
mod lu2015;
mod ren2021;
mod transfer_matrix;

pub use chen2024::Chen2024Section;
pub use discrepancy_fdm::DiscrepancyFdmSection;
pub use discrepancy_inkjet::DiscrepancyInkjetSection;
pub use discrepancy_thermal::DiscrepancyThermalSection;
pub use fdm_virtual::FdmVirtualSection;
pub use lu2015::Lu2015Section;

pub use ren2021::Ren2021Section;
pub use transfer_matrix::TransferMatrixSection;

use pipeline::{Registry, StageError};
use polars::prelude::{Column, DataFrame, IntoColumn, NamedFrom, Series};
use tables::report::comparison;

/// Registers every report-section kind.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(Ren2021Section));
    registry.register(Box::new(Lu2015Section));
    registry.register(Box::new(Chen2024Section));
    registry.register(Box::new(DiscrepancyFdmSection));
    registry.register(Box::new(DiscrepancyInkjetSection));
    registry.register(Box::new(DiscrepancyThermalSection));
    registry.register(Box::new(FdmVirtualSection));
    registry.register(Box::new(TransferMatrixSection));
}

/// One comparison row.
pub(crate) struct Row {
    pub(crate) section: &'static str,
    pub(crate) item: String,
    pub(crate) paper: Option<f64>,
    pub(crate) ours: f64,
    pub(crate) unit: &'static str,
    pub(crate) source: String,
}

/// The long comparison table: section, item, paper_value (null where the paper has
/// none), our_value, unit, source.
pub(crate) fn comparison_frame(rows: &[Row]) -> Result<DataFrame, StageError> {
    let str_col = |name: &str, v: Vec<String>| -> Column { Series::new(name.into(), v).into_column() };
    let columns = vec![
        str_col(comparison::section, rows.iter().map(|r| r.section.to_string()).collect()),
        str_col(comparison::item, rows.iter().map(|r| r.item.clone()).collect()),
        Series::new(comparison::paper_value.into(), rows.iter().map(|r| r.paper).collect::<Vec<Option<f64>>>())
            .into_column(),
        Series::new(comparison::our_value.into(), rows.iter().map(|r| r.ours).collect::<Vec<f64>>()).into_column(),
        str_col(comparison::unit, rows.iter().map(|r| r.unit.to_string()).collect()),
        str_col(comparison::source, rows.iter().map(|r| r.source.clone()).collect()),
    ];
    DataFrame::new(rows.len(), columns).map_err(|source| StageError::Table { path: "comparison".into(), source })
}
