#!/usr/bin/env bash
# Reproduces the pre-training recipe that reaches the 80% target (reported in docs/experiments/rounds.md, "Data: rounds
# of learned-policy data"): 82.3% [79.8-84.5] on 1,000 reporting scenes for the selected seed, 80.4% on average over three
# seeds. 10,000 collected episodes: 8,000 scripted, then
# 667 + 667 episodes from two policies trained on the scripted data, then 666 from a policy trained on all of
# that. Training is Monte-Carlo QT-Opt (--n-step 8 spans the whole episode) with the learning rate
# cosine-decayed to 5% over 6,000 steps; the final network has a wider head (hidden 256, 3 layers).
# About 42 minutes of training on 2 cores, counting the 18 behind ckpt:base. Outputs go to $NSL_HOME; every
# step resumes when run again. Not re-run end to end: the reported numbers come from these commands run one
# by one in one workspace (where the third round's dataset is called grasp-base-learned3c), some of them
# sharing the machine, and a different thread count can change floating-point sums.
set -euo pipefail
cd "$(dirname "$0")/../.."
NSL=${NSL:-.venv/bin/nsl}
MC="--steps 6000 --lr-decay 6000 --n-step 8 --crop 2 --net action_dims=0,1,3"
SCRIPTED="--data grasp-base-oracle=0.35 --data grasp-base-noisy=0.15 --data grasp-base-random=0.15"

# 8,000 scripted base-task episodes on the train objects (oracle:0.5 4,000, oracle:1.0 2,000, random 2,000).
NSL=$NSL bash scripts/collect_base_data.sh

# Round 1, two collectors trained on the scripted data only, 667 episodes each (10% random actions):
#   the shipped one-step base (ckpt:base, nsl/assets/base) ...
$NSL collect --shift base --episodes 667 --policy ckpt:base --epsilon 0.1 \
  --data grasp-base-learned --seed 4 --workers 2 --num-envs 8
#   ... and a Monte-Carlo run on the scripted data (67% on the selection scenes).
$NSL train --data grasp-base-oracle=0.5 --data grasp-base-noisy=0.25 --data grasp-base-random=0.25 $MC \
  --eval-every 2000 --eval-scenes 2000 --eval-episodes 50 --patience 100 --name s1-n8-cos6k
$NSL collect --shift base --episodes 667 --policy ckpt:s1-n8-cos6k@6000 --epsilon 0.1 \
  --data grasp-base-learned2 --seed 4 --workers 2 --num-envs 8

# Round 2: a policy trained on the scripted data and round 1 collects 666 more.
$NSL train $SCRIPTED --data grasp-base-learned:667=0.175 --data grasp-base-learned2:667=0.175 $MC --name c1-r1p
$NSL collect --shift base --episodes 666 --policy ckpt:c1-r1p@6000 --epsilon 0.1 \
  --data grasp-base-learned3 --seed 5 --workers 2 --num-envs 8

# The base: all 10,000 episodes, the learned rounds together at 35% of each batch, a wider head; two seeds.
for seed in 0 1; do
  $NSL train $SCRIPTED --data grasp-base-learned:667=0.12 --data grasp-base-learned2:667=0.12 \
    --data grasp-base-learned3:666=0.11 $MC --net hidden=256 --net head_layers=3 --seed $seed \
    --name c1-final-h256$([ $seed = 0 ] || echo -seed$seed)
done

# Selection on 1,000 scenes of seed 3000 (80.5 / 81.2% here: seed 1 selected); docs/experiments/rounds.md reports
# seed 2000.
$NSL eval --checkpoint ckpt:c1-final-h256@6000,ckpt:c1-final-h256-seed1@6000 --episodes 1000 --workers 2 --seed 3000
