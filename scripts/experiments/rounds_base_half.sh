# The base half of the study's protocol in the workspace of pretrain_base_rounds.sh: the shipped base's 44,000
# pre-training episodes at half their recorded weights (docs/experiments/fine-tuning.md, "Fine-tuning the rounds base").
# Sourced by the protocol scripts; each adds `--data TARGET=0.5`.
BASE="--data grasp-base-oracle=0.175 --data grasp-base-noisy=0.075 --data grasp-base-random=0.075
      --data grasp-rounds-1:4000=0.01945 --data grasp-rounds-2:8000=0.03889 --data grasp-rounds-3:12000=0.05833
      --data grasp-rounds-4:12000=0.05833"
