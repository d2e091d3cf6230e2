"""The DSFEC paper's published numbers (Tables 1-3, arXiv 2412.07411), for side-by-side reports."""

TABLE1 = {  # model: mAP, AP@4, GFLOPs, params, runtime on V100 and Raspberry Pi 4 (ms)
    "baseline": {"mAP": 23.9, "AP4": 39.3, "gflops": 20.72, "params": 2.63e6, "v100_ms": 22.51, "raspi_ms": 1276},
    "dsfec_l": {"mAP": 27.4, "AP4": 42.8, "gflops": 18.96, "params": 2.37e6, "v100_ms": 19.15, "raspi_ms": 1136},
    "dsfec_m": {"mAP": 27.4, "AP4": 41.9, "gflops": 8.29, "params": 0.58e6, "v100_ms": 18.04, "raspi_ms": 668},
    "dsfec_s": {"mAP": 24.8, "AP4": 39.0, "gflops": 4.45, "params": 0.30e6, "v100_ms": 17.2, "raspi_ms": 325},
}
TABLE2 = {  # stem filters: mAP, stem GFLOPs, runtime (ms), memory (MB)
    32: {"mAP": 27.4, "gflops": 1.06, "runtime_ms": 33, "memory_mb": 4.32},
    16: {"mAP": 27.3, "gflops": 0.48, "runtime_ms": 22, "memory_mb": 2.74},
    12: {"mAP": 26.5, "gflops": 0.34, "runtime_ms": 13, "memory_mb": 2.35},
    8: {"mAP": 25.4, "gflops": 0.19, "runtime_ms": 9, "memory_mb": 1.96},
}
TABLE3 = {  # blocks in stage 2 of DSFEC-L: mAP, model GFLOPs, model runtime on the Pi (ms)
    6: {"mAP": 27.4, "gflops": 18.96, "raspi_ms": 1136},
    3: {"mAP": 26.17, "gflops": 17.4, "raspi_ms": 1027},
}
RASPI_S_OVER_BASELINE = TABLE1["dsfec_s"]["raspi_ms"] / TABLE1["baseline"]["raspi_ms"]  # 0.255
