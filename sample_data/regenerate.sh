#!/bin/sh
# Regenerate every sample survey in sample_data/ from its SIM file in configs/.
# Output is byte-identical on every run and machine with the same library versions
# (tests/test_simulate_output.py checks the committed files against a fresh run).
# Usage (from anywhere): sample_data/regenerate.sh
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(dirname "$here")
for pair in seed_line:sample_seed_line grid_ros2:sample_grid_ros2 markov_csv:sample_markov_csv; do
    dir=${pair%%:*}
    sim=${pair#*:}
    rm -rf "$here/$dir"
    gravsurvey simulate "$root/configs/$sim.yaml" -o "$here/$dir"
    echo "sample_data/$dir <- configs/$sim.yaml"
done
