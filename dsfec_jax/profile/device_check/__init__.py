"""The device check (`python -m dsfec_jax.profile.device_check`): a few training steps and an
inference of every family on the backend present, compared with the CPU on the same inputs and
weights, with throughput, peak memory and the kernel path each program took.

workload.py: what one model brings (its trainer, batches, first state); sides.py: one model run
on one device; verdict.py: the comparison and the kernels rule; report.py: the printed lines and
the record. The entry point (__main__.py) builds the workloads from the modality records.
"""
