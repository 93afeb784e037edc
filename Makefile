# amrepro: `make run` reproduces everything, `make test` checks everything.
# One build profile (release) for run, test and bench, so CI compiles once.

CARGO_TARGET_DIR ?= $(HOME)/.cache/amrepro-target
export CARGO_TARGET_DIR
AMREPRO_DATA ?= $(abspath data)
export AMREPRO_DATA
VENV ?= $(HOME)/.cache/amrepro-venv
export AMREPRO_PYTHON := $(VENV)/bin/python
OUT ?= out
BIN := $(CARGO_TARGET_DIR)/release/amrepro
SPECS := $(sort $(wildcard specs/*.toml))
STUDY_SPECS := $(sort $(wildcard specs/studies/*.toml))

.PHONY: run build test check lint bench docs fuzz clean

## run: build, run every shipped spec into $(OUT)/, print where the report is
run: build
	@for spec in $(SPECS); do $(BIN) run --out $(OUT) $$spec || exit 1; done
	@echo "published tables: $(OUT)/fdm/, $(OUT)/fdm_virtual/, $(OUT)/inkjet/, $(OUT)/thermal/, $(OUT)/discrepancy/ (see docs/OUTPUTS.md)"
	@echo "open the report:  $(OUT)/report/index.html"

build:
	cargo build --release --workspace --bin amrepro

## test: format and lint checks, then every test (installs duckdb/polars for Python first)
test: $(VENV)/.installed lint
	cargo test --release --workspace

lint:
	cargo fmt --all --check
	cargo clippy --release --workspace --all-targets -- -D warnings

$(VENV)/.installed: requirements-test.txt
	python3 -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-test.txt
	touch $@

## bench: criterion benchmarks of the hot paths
bench:
	cargo bench --workspace

## fuzz: every cargo-fuzz target for FUZZ_SECONDS each (nightly + cargo-fuzz; fuzz/README.md)
FUZZ_SECONDS ?= 180
FUZZ_TARGETS := fdm_widths fdm_lines inkjet_scans thermal_sequence thermal_truth fsu_raw png_frame spec
fuzz:
	cd fuzz && for t in $(FUZZ_TARGETS); do \
		cargo +nightly fuzz run -O $$t corpus/$$t seeds/$$t -- -max_total_time=$(FUZZ_SECONDS) || exit 1; done

## docs: regenerate docs/STAGES.md (the registry) and docs/COLUMNS.md (the published tables' declared columns)
docs: build
	$(BIN) stages --markdown > docs/STAGES.md
	$(BIN) outputs --markdown $(SPECS) $(STUDY_SPECS) > docs/COLUMNS.md

clean:
	rm -rf $(OUT)
