//! Transfer among several printers, end to end through the shipped
//! `specs/ren2021_transfer.toml` cut to two printers (the real Taz 6 and the Taz 6 with a
//! slower melt, [`TEST_MATRIX`]): the published table has the columns analysts query,
//! the guard is never worse than single-printer learning beyond its interval, the
//! figure and the section are drawn; bad parameters are named.

mod common;

use common::*;
use tables::fdm::{transfer_matrix, transfer_matrix_rows};

#[test]
fn the_guard_never_hurts_beyond_its_interval_on_the_real_lines() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "ren2021_transfer", &data_root().join("fsu-linewidth"));
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    use transfer_matrix as t;
    let table = read_table(&tmp.path().join("out/fdm/transfer_matrix.parquet"));
    let names: Vec<String> = table.get_column_names().iter().map(|c| c.to_string()).collect();
    let wanted = [
        t::sources,
        t::target,
        t::n_train,
        t::method,
        t::median_rmse_mm,
        t::improvement_pct,
        t::ci_lo_pct,
        t::ci_hi_pct,
    ];
    assert!(wanted.iter().all(|w| names.iter().any(|n| n == w)), "{names:?}");
    // Two printers: two ordered pairs × 8 training sizes × (4 methods and the bound in
    // hindsight).
    assert_eq!(table.height(), 2 * 8 * 5);
    let (method, hi, lo) = (strings(&table, t::method), floats(&table, t::ci_hi_pct), floats(&table, t::ci_lo_pct));
    let imp = floats(&table, t::improvement_pct);
    for i in (0..table.height()).filter(|&i| method[i] == "guarded") {
        assert!(hi[i] >= 0.0, "row {i}: the guard is worse than single beyond its interval");
        assert!(lo[i] <= imp[i] && imp[i] <= hi[i] + 1e-9, "row {i}: the estimate lies in its interval");
    }
    assert!(strings(&table, t::kinematics).iter().all(|k| k == "target_pair"), "the spec's kinematics rule");
    let singles = (0..table.height()).filter(|&i| method[i] == "single");
    assert!(singles.clone().count() == 16 && singles.clone().all(|i| imp[i] == 0.0));
    let run = tmp.path().join("out/runs/ren2021_transfer");
    assert!(run.join("matrix_fig/transfer_matrix.png").is_file());
    let section = std::fs::read_to_string(run.join("comparison/section.html")).unwrap();
    assert!(section.contains("negative-transfer guard"), "{section}");
    assert!(section.contains("that the same training lines give without prior"), "{section}");
    let rows = read_table(&tmp.path().join("out/fdm/transfer_matrix_rows.parquet"));
    let prior = strings(&rows, transfer_matrix_rows::prior);
    let rows_method = strings(&rows, transfer_matrix_rows::method);
    let n_train: Vec<i64> =
        rows.column(transfer_matrix_rows::n_train).unwrap().i64().unwrap().into_no_null_iter().collect();
    assert!((0..rows.height()).filter(|&i| rows_method[i] == "guarded" && n_train[i] == 1).all(|i| prior[i] == "none"));
}

#[test]
fn unknown_blob_printer_an_unknown_kinematics_rule_and_a_reused_printer_name_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "ren2021_transfer", &data_root().join("fsu-linewidth"));
    let text = std::fs::read_to_string(&spec).unwrap();
    let typo = text.replace("bootstrap_draws = 400,", "blob_printers = \"taz7\",");
    std::fs::write(&spec, typo).unwrap();
    let err = fails(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    assert!(err.contains("taz7") && err.contains("matrix"), "{err}");
    let rule = text.replace("kinematics = \"target_pair\"", "kinematics = \"target\"");
    std::fs::write(&spec, rule).unwrap();
    let err = fails(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    assert!(err.contains("kinematics") && err.contains("`target`") && err.contains("target_pair"), "{err}");
    let same = text.replace("printer = \"taz6-slow-melt\"", "printer = \"taz6\"");
    std::fs::write(&spec, same).unwrap();
    let err = fails(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    assert!(err.contains("new printer") && err.contains("taz6_slow_melt"), "{err}");
    // Two inputs that are the same printer by name: the second's dataset.toml is named.
    let again = text
        .replace("inputs = [\"taz6\", \"taz6_slow_melt\"]", "inputs = [\"taz6\", \"taz6_slow_melt\", \"taz6_again\"]")
        + "\n[stage.taz6_again]\nkind = \"fdm.import\"\ninputs = [\"fsu_raw\"]\nparams = { printer = \"taz6\" }\n";
    std::fs::write(&spec, again).unwrap();
    let err = fails(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    assert!(err.contains("dataset.toml:field printer: expected a printer other than input `taz6`'s, `taz6`"), "{err}");
}
