"""One-shot NAS: search spaces as data (space.py, spaces.py), the paper's constrained evolution
(evolution.py) and Optuna's NSGA-II (nsga.py) over the same space and scores."""
