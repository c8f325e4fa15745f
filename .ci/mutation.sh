#!/bin/sh
# Mutation testing of the safety core (issue 12), after panda's tests/safety/mutation.sh: every
# mutant cargo-mutants makes in the files below must be caught by the library's unit tests, or
# be listed in the README with the reason it is equivalent.
#
# Needs cargo-mutants (`cargo install cargo-mutants`). Not in CI: each mutant rebuilds and runs
# the library's tests (tens of seconds on two cores), and these files give a few hundred.
# Extra arguments go to cargo-mutants, e.g. `.ci/mutation.sh --list` to see the mutants,
# `-j 2` for two at a time. Results: target/mutants/mutants.out/{caught,missed,timeout}.txt.
set -eu
cd "$(dirname "$0")/.."
exec cargo mutants --package steering-ecu \
    --file src/protocol/e2e.rs \
    --file src/steering.rs \
    --file src/faults.rs \
    --file src/ecu.rs \
    --timeout 120 \
    --output target/mutants \
    "$@" -- --lib
