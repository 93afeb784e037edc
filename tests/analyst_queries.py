"""Reads every published table of the runs under OUT with DuckDB and Polars (Python),
checks row counts against the run manifests, and runs every example query of
docs/OUTPUTS.md (```sql blocks with DuckDB, ```python blocks as scripts).

Usage: python analyst_queries.py OUT_DIR OUTPUTS_MD   (queries run with cwd = parent of OUT_DIR)
       python analyst_queries.py --examples DOC_MD     (only the examples of DOC_MD, in the cwd)
"""
import json
import pathlib
import re
import sys

import duckdb
import polars as pl


def published_tables(out_dir: pathlib.Path):
    for manifest_path in sorted(out_dir.glob("runs/*/manifest.json")):
        manifest = json.loads(manifest_path.read_text())
        for stage in manifest["stages"]:
            for target in stage["published"].values():
                if target.endswith(".parquet"):
                    yield manifest["run"], stage["stage"], out_dir / target


def check_tables(out_dir: pathlib.Path) -> int:
    count = 0
    for run, stage, path in published_tables(out_dir):
        rows_duckdb = duckdb.sql(f"select count(*) from read_parquet('{path}')").fetchone()[0]
        frame = pl.read_parquet(path)
        assert rows_duckdb == frame.height > 0, f"{path}: duckdb {rows_duckdb} rows, polars {frame.height}"
        meta = duckdb.sql(f"select key::varchar, value::varchar from parquet_kv_metadata('{path}')").fetchall()
        keys = {k for k, _ in meta}
        assert {"amrepro_tool_version", "amrepro_stage", "amrepro_stage_hash", "amrepro_params_hash", "amrepro_schema_version"} <= keys, f"{path}: metadata {keys}"
        print(f"ok  {path.relative_to(out_dir)}  {rows_duckdb} rows  (run {run}, stage {stage})")
        count += 1
    assert count > 0, f"no published tables under {out_dir}"
    return count


def run_examples(doc: pathlib.Path) -> int:
    text = doc.read_text()
    sql_blocks = re.findall(r"```sql\n(.*?)```", text, re.S)
    py_blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert sql_blocks and py_blocks, f"{doc}: expected ```sql and ```python examples"
    for sql in sql_blocks:
        result = duckdb.sql(sql).fetchall()
        assert result, f"query returned no rows:\n{sql}"
        print(f"ok  sql example ({len(result)} rows): {sql.strip().splitlines()[0]}")
    for code in py_blocks:
        exec(compile(code, str(doc), "exec"), {})
        print(f"ok  python example: {code.strip().splitlines()[0]}")
    return len(sql_blocks) + len(py_blocks)


if __name__ == "__main__":
    if sys.argv[1] == "--examples":
        examples = run_examples(pathlib.Path(sys.argv[2]))
        print(f"{examples} passed, 0 failed")
        sys.exit(0)
    out_dir, doc = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    tables = check_tables(out_dir)
    examples = run_examples(doc)
    print(f"{tables + examples} passed, 0 failed")
