#!/bin/sh
# `sasmi calibrate --searches 2` from seafloor_only to one other sonar's floor chips (SASSED by default, or klsg),
# split by scene group among themselves, over FLOOR_KNOBS (benchmarks/knob_lists.sh): two searches sharing MINUTES,
# the one a classifier tells least from the train floors kept (RUN/preset.toml), the other written beside it
# (RUN/search-K.toml). 400 renders of each and of seafloor_only against the held-back floors: `sasmi stats --check`
# and `sasmi evaluate` (φ-FID ratio, precision / recall, two-sample test). --profile-trials 0: the profiles judge the
# calibrated knobs after the preset is chosen and change no preset.
#
#     benchmarks/calibrate_floor_searches.sh [RUNS] [MINUTES] [SONAR]      (defaults: runs 60 sassed;
#     RUN = RUNS/calibrate-SONAR-searches)
set -eu
RUNS=${1:-runs}
MINUTES=${2:-60}
SONAR=${3:-sassed}
SASMI=.venv/bin/sasmi
DATA=../shared/data/sonar-chips
. benchmarks/knob_lists.sh
run=$RUNS/calibrate-$SONAR-searches

.venv/bin/python benchmarks/sonar_floors.py "$DATA" "$SONAR" "$RUNS/$SONAR"
[ -d "$RUNS/$SONAR-split" ] || $SASMI split "$RUNS/$SONAR" --seed 0 --out "$RUNS/$SONAR-split"
TRAIN=$(ls "$RUNS/$SONAR-split/train/seafloor" | wc -l)  # --chips leaves 8 real chips out of each trial's draw
$SASMI calibrate --real "$RUNS/$SONAR-split/train/seafloor" --preset seafloor_only --params "$FLOOR_KNOBS" \
    --chips $(( TRAIN - 8 < 16 ? TRAIN - 8 : 16 )) --minutes "$MINUTES" --searches 2 --contenders 1 \
    --profile-trials 0 --out "$run"
$SASMI render "$run/preset.toml" --count 400 --size 128 --out "$run/renders"
for other in "$run"/search-*.toml; do
    $SASMI render "$other" --count 400 --size 128 --out "${other%.toml}-renders"
done
[ -d "$RUNS/seafloor-renders" ] || $SASMI render seafloor_only --count 400 --size 128 --out "$RUNS/seafloor-renders"
$SASMI stats "$RUNS/$SONAR-split/validation/seafloor" "$run/renders" "$run"/search-*-renders \
    "$RUNS/seafloor-renders" --check || true
$SASMI evaluate --real "$RUNS/$SONAR-split/validation/seafloor" --out "$run/two-sample" \
    --set kept="$run/renders" $(for r in "$run"/search-*-renders; do echo "--set $(basename "$r" -renders)=$r"; done) \
    --set seafloor_only="$RUNS/seafloor-renders"
