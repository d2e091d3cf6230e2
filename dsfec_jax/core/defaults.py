"""Run-time defaults shared by the command line, the predictors' callers and the benchmarks."""

# Pillar slots at run time: radar frames fill fewer than 1000, and the weights do not depend on
# the slot count (training and the paper sizes use the config's own max_pillars).
RUN_PILLARS = 2048

# eval / predict / ship of point-cloud models keep detections scoring at least this (range-Doppler
# models: the paper's 0.001, models/yolo_rd/decode.EVAL_CONF)
POINT_SCORE_THRESHOLD = 0.05
