#!/bin/sh
# Mutation testing of the safety core, after panda's tests/safety/mutation.sh: every
# mutant cargo-mutants makes in the files below must be caught by the library's unit tests, or
# be listed in src/FIRMWARE.md ("Mutation testing") with the reason it is equivalent.
#
# Needs cargo-mutants (`cargo install cargo-mutants`). Not in CI: each mutant rebuilds and runs
# the library's tests (about 16 s on two cores), and these files give about 620.
#
#   .ci/mutation.sh                          all of them, results in target/mutants
#   FILES=src/faults.rs .ci/mutation.sh -j 1 one file, results in target/mutants/faults
#   .ci/mutation.sh --list                   the mutants only
#   FILES=src/steering/mod.rs .ci/mutation.sh --re 'mod.rs:(5[89]\d|[6-9]\d\d):'
#                                            part of a file: --re matches "file:line:col: ..."
#
# Arguments after `-- --` go to the test binary: a filter of the tests that exercise the file
# makes each mutant's test run short. The EPOS4 link's runtime (105 mutants: `LimitSide` and
# everything from `set_power` to the end of `impl Epos4Link`; the configuration is in
# epos4/config.rs), as measured: the library's link, steering and ECU tests without the link's
# 100 000-case frame property (4 min on two shared cores); run the missed ones again with it
# (`--iterate`, without the --skip) if it might catch them:
#   CARGO_PROFILE_DEV_OPT_LEVEL=0 FILES=src/canopen/epos4.rs .ci/mutation.sh --in-place \
#       --re 'epos4.rs:(19\d|20[0-3]|55[5-9]|5[6-9]\d|[6-9]\d\d|10[0-5]\d):' \
#       -- -- canopen:: ecu:: --skip decoders_and_link_accept_any_frame
# The state machine and the ECU the same way, with `-- -- steering:: ecu:: --skip ...` (8 and
# 7 min). Line ranges move with the code: check them against `--list` before a run.
# (CARGO_PROFILE_DEV_OPT_LEVEL=0 builds the library alone unoptimised, its dependencies as
# before: each mutant built in 2-11 s in that run.)
#
# On shared cores run it under `nice -n 10`; two files can run side by side, each in its own
# copy of the tree with `--in-place` (its own target directory: never a shared one; `-j` and
# `--in-place` exclude each other).
#
# Extra arguments go to cargo-mutants (`-j 1`, `--list`, `--re REGEX`, `--in-place` in a copy
# of the tree made for the run). Results: <output>/mutants.out/{caught,missed,timeout,
# unviable}.txt. Only the library is built and tested (`--lib` to every cargo call: the binary
# is a host stub, building it too doubles each mutant's build). cargo-mutants builds a copy of
# the tree in its own target directory, so CARGO_TARGET_DIR is not passed on (a shared one
# would rebuild the real tree's library after every mutant).
set -eu
cd "$(dirname "$0")/.."
# The state machine and its detectors, src/steering/*.rs, and the ECU and its drives,
# src/ecu/*.rs (the globs are expanded below; their test files are only reachable through
# #[cfg(test)] and give no mutants).
FILES=${FILES:-"src/protocol/e2e.rs src/steering/*.rs src/faults.rs src/ecu/*.rs"}
OUT=target/mutants
FILE_ARGS=""
for f in $FILES; do
    FILE_ARGS="$FILE_ARGS --file $f"
done
case "$FILES" in
    *" "*) ;;
    # src/canopen/epos4.rs -> canopen-epos4, src/faults.rs -> faults
    *) OUT="$OUT/$(printf '%s' "${FILES%.rs}" | sed 's|^src/||; s|/|-|g')" ;;
esac
unset CARGO_TARGET_DIR
# shellcheck disable=SC2086 # FILE_ARGS is a list of words
mkdir -p "$OUT"
exec cargo mutants --package steering-ecu $FILE_ARGS \
    --timeout 120 \
    --output "$OUT" \
    --cargo-arg=--lib \
    "$@"
