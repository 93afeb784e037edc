//! The work units of split stages (`pipeline::units`). Power studies: a study's draws
//! on each base, cut into blocks of consecutive draws, each block's per-draw rows
//! written as one Parquet part, and the parts read back in order for the merge. A
//! draw's result depends only on its base and its place in the base's draw list, never
//! on the block it falls in, so the cut changes how the work is spread, not what it
//! gives. Per-data-set stages: one unit per data set, whose tables the merge stacks.

use std::ops::Range;
use std::path::PathBuf;

use discrepancy::power::{summarize, DrawScore, Outcome};
use pipeline::artifact::read_parquet;
use pipeline::schema::Table;
use pipeline::{StageContext, StageError, Unit};
use polars::prelude::{DataFrame, IntoColumn, NamedFrom, PlSmallStr, Series};
// A study's part and draws have the FDM study's columns first in every domain
// (`tables::discrepancy`), so the shared code names them through those.
use tables::discrepancy::fdm::{power_draws, power_part};
use tables::discrepancy::power;

use crate::discrepancy_tables::{power_frame, PowerOf};
use crate::table::{f64s, opt_bools, strs};

/// The file of a unit's part in its folder (each split kind declares its part's columns
/// as a table of this name).
pub const PART_TABLE: &str = "part";

pipeline::params! {
    /// How a power study's draws are cut into work units, as every study declares it.
    pub struct UnitSize {
        /// Draws per work unit of a spread-out run (`amrepro plan`, docs/SCALE.md); how the work is cut, not what it gives.
        pub draws_per_unit: i64 [1, 100_000] = 50,
    }
}

/// How many strengths a comma-separated list names (the cells of one effect).
pub fn listed(list: &str) -> usize {
    list.split(',').filter(|s| !s.trim().is_empty()).count()
}

/// Writes one unit's part of a power study on a virtual printer: its rows of
/// `power_draws.parquet` and whether each draw's interval covered the truth.
pub fn write_study_part(
    ctx: &mut StageContext,
    draws: DataFrame,
    covered: Vec<Option<bool>>,
) -> Result<(), StageError> {
    let mut part = draws;
    part.with_column(Series::new(power_part::covered.into(), covered).into_column())
        .map_err(|source| StageError::Table { path: ctx.output_dir().join(PART_TABLE), source })?;
    ctx.write_table(power_part::TABLE.name, &mut part)?;
    Ok(())
}

/// The merge of a power study on a virtual printer (one base, [`write_study_part`]):
/// `power_draws.parquet` is the parts' rows, `power.parquet` their summary; `effects`
/// are the study's effect names (`none` is added).
pub fn merge_study(ctx: &mut StageContext, parts: &[PathBuf], effects: &[&'static str]) -> Result<(), StageError> {
    let all = read_parts(parts)?;
    let file = ctx.output_dir().join("parts");
    let (base, effect, outcome) = (
        strs(&all, power_part::base, &file)?,
        strs(&all, power_part::effect, &file)?,
        strs(&all, power_part::outcome, &file)?,
    );
    let strength = f64s(&all, power_part::strength, &file)?;
    let covered = opt_bools(&all, power_part::covered, &file)?;
    let bad = |what: &str, value: &str| StageError::BadInput {
        file: file.clone(),
        location: None,
        expected: format!("a known {what}, got `{value}`"),
    };
    let scores = (0..all.height())
        .map(|i| {
            let name = std::iter::once("none").chain(effects.iter().copied()).find(|e| *e == effect[i]);
            Ok(DrawScore {
                effect: name.ok_or_else(|| bad("effect", &effect[i]))?,
                strength: strength[i],
                outcome: Outcome::parse(&outcome[i]).ok_or_else(|| bad("outcome", &outcome[i]))?,
                covered: covered[i],
            })
        })
        .collect::<Result<Vec<_>, StageError>>()?;
    let label = base.first().cloned().unwrap_or_default();
    let of = PowerOf { base: &label, noise: "virtual", own_causes: "none" };
    ctx.write_table(power::TABLE.name, &mut power_frame(&[(of, summarize(&scores))])?)?;
    ctx.write_table(power_draws::TABLE.name, &mut without(&all, &[power_part::covered])?)?;
    Ok(())
}

/// The blocks of a study of `draws` draws on each of `bases` bases, `per_unit` draws
/// each (the last block of a base may be shorter); a base with no draws is one empty
/// unit, so that every base is visited. Keys name the base when there are several.
pub fn draw_units(bases: usize, draws: usize, per_unit: usize) -> Vec<Unit> {
    (0..bases)
        .flat_map(|b| {
            block_ranges(draws, per_unit).map(move |r| Unit {
                key: match bases {
                    1 => format!("draws {}-{}", r.start, r.end.saturating_sub(1)),
                    _ => format!("base {b} draws {}-{}", r.start, r.end.saturating_sub(1)),
                },
                cost: r.len().max(1) as f64,
            })
        })
        .collect()
}

/// The design of a power study as its units see it: `null_draws` plus `draws` per
/// strength listed in each of `strength_lists` (one comma-separated list per effect).
pub struct StudySize<'a> {
    /// Draws per base with nothing injected.
    pub null_draws: i64,
    /// Draws per base, effect and strength.
    pub draws: i64,
    /// Each studied effect's list of strengths.
    pub strength_lists: Vec<&'a str>,
    /// How the draws are cut.
    pub unit_size: &'a UnitSize,
}

/// The units of a power study on each of `bases` bases, in blocks of `draws_per_unit`
/// ([`draw_units`]).
pub fn study_units(size: &StudySize, bases: usize) -> Vec<Unit> {
    let cells: usize = size.strength_lists.iter().map(|list| listed(list)).sum();
    let draws = size.null_draws as usize + cells * size.draws as usize;
    draw_units(bases, draws, size.unit_size.draws_per_unit as usize)
}

/// Unit `index` of [`study_units`] as (base, range of its draws) in a study of `draws`
/// draws per base.
pub fn study_unit_draws(unit_size: &UnitSize, index: usize, draws: usize) -> (usize, Range<usize>) {
    unit_draws(index, draws, unit_size.draws_per_unit as usize)
}

/// One unit per data set of a stage that reads `inputs` folders, `per_set` of them a
/// set (a thermal print is a sequence and its monitor); a last, incomplete set is a unit
/// too, so that the stage can refuse it when it runs.
pub fn data_set_units(inputs: usize, per_set: usize) -> Vec<Unit> {
    (0..inputs.div_ceil(per_set.max(1))).map(|u| Unit { key: format!("data set {u}"), cost: 1.0 }).collect()
}

/// Merges the parts of a per-data-set stage: each of `tables` is the parts' rows
/// stacked in unit order.
pub fn merge_tables(ctx: &mut StageContext, parts: &[PathBuf], tables: &[&Table]) -> Result<(), StageError> {
    for table in tables {
        let files: Vec<PathBuf> = parts.iter().map(|p| p.join(table.file())).collect();
        ctx.write_table(table.name, &mut stack(&files)?)?;
    }
    Ok(())
}

/// Unit `index` of [`draw_units`] as (base, range of its draws).
pub fn unit_draws(index: usize, draws: usize, per_unit: usize) -> (usize, Range<usize>) {
    let per_base = block_ranges(draws, per_unit).count();
    let block = block_ranges(draws, per_unit).nth(index % per_base).expect("index within the base's blocks");
    (index / per_base, block)
}

fn block_ranges(draws: usize, per_unit: usize) -> impl Iterator<Item = Range<usize>> + Clone {
    let per_unit = per_unit.max(1);
    let blocks = draws.div_ceil(per_unit).max(1);
    (0..blocks).map(move |k| (k * per_unit).min(draws)..((k + 1) * per_unit).min(draws))
}

/// The parts, stacked in unit order into one single-chunk table.
pub fn read_parts(parts: &[PathBuf]) -> Result<DataFrame, StageError> {
    stack(&parts.iter().map(|dir| dir.join(format!("{PART_TABLE}.parquet"))).collect::<Vec<_>>())
}

/// The Parquet files, stacked in order into one single-chunk table.
fn stack(files: &[PathBuf]) -> Result<DataFrame, StageError> {
    let mut stacked: Option<DataFrame> = None;
    for path in files {
        let part = read_parquet(path)?;
        match &mut stacked {
            None => stacked = Some(part),
            Some(all) => {
                all.vstack_mut(&part).map_err(|source| StageError::Table { path: path.to_path_buf(), source })?;
            }
        }
    }
    let mut all = stacked.unwrap_or_default();
    all.rechunk_mut();
    Ok(all)
}

/// `df` without the columns `drop` (the parts' bookkeeping columns).
pub fn without(df: &DataFrame, drop: &[&str]) -> Result<DataFrame, StageError> {
    let keep: Vec<PlSmallStr> =
        df.get_column_names().into_iter().filter(|n| !drop.contains(&n.as_str())).cloned().collect();
    df.select(keep).map_err(|source| StageError::Table { path: "(merged parts)".into(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_cover_every_draw_of_every_base_once_in_order() {
        let units = draw_units(2, 7, 3);
        assert_eq!(units.len(), 6);
        let mut seen = Vec::new();
        for i in 0..units.len() {
            let (base, range) = unit_draws(i, 7, 3);
            seen.extend(range.map(|d| (base, d)));
        }
        let expected: Vec<(usize, usize)> = (0..2).flat_map(|b| (0..7).map(move |d| (b, d))).collect();
        assert_eq!(seen, expected);
        assert_eq!(units[2].key, "base 0 draws 6-6");
        assert_eq!(units[2].cost, 1.0);
    }

    #[test]
    fn a_base_without_draws_is_one_empty_unit() {
        assert_eq!(draw_units(3, 0, 10).len(), 3);
        assert_eq!(unit_draws(2, 0, 10), (2, 0..0));
    }
}
