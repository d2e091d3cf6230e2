"""The PyTorch peer of `experiments.peer_speed`: ultralytics' YOLOv8 built from its own yaml, timed
as a worker the lead process drives. It runs under an interpreter that has torch and ultralytics
(neither is a dependency of the project), so it imports nothing of dsfec_jax or jax.

    PEER_PYTHON experiments/peer_torch.py --mode train --model yolov8n --threads 2 --batches B.npz
    PEER_PYTHON experiments/peer_torch.py --mode forward --model yolov8n --threads 1 --hw 256,64 --channels 3
    PEER_PYTHON experiments/peer_torch.py --mode forward --twin CASE.npz --threads 1

Protocol (what makes the lead's interleaving possible): after building, the worker prints one JSON
line {"ready": ...}; then each line "N" on stdin runs N timed calls and answers {"ms": [...]};
"quit" or end of input exits.

- train: one training step as ultralytics' trainer makes it on CPU (float32, no AMP): the
  model's own loss (v8DetectionLoss with the default hyperparameters), backward, and SGD with
  Nesterov momentum 0.937; on the lead's batches (`--batches`, an .npz of the project's own
  augmented batches: images B x H x W x C, boxes xyxy pixels, labels, mask), cycled.
- forward: the inference network as ultralytics deploys it, `model.fuse()` (BatchNorm folded
  into the convolutions) in eval mode under `torch.inference_mode`, traced and frozen with
  TorchScript, on a fixed random image. With `--twin CASE.npz` (from `experiments.twin_export`):
  the PyTorch twin of a project network with the project's weights (experiments/peer_twins.py),
  traced and frozen, on the case's input; the worker checks it against the case's JAX outputs
  before it answers ready (and exits if they differ), and the ready line carries the check.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time


def _threads(threads: int) -> None:
    """Pin to the first `threads` CPUs this process may use and size torch's pools to them."""
    import torch

    cpus = sorted(os.sched_getaffinity(0))[:threads]
    os.sched_setaffinity(0, cpus)
    torch.set_num_threads(threads)
    torch.set_num_interop_threads(1)


def _model(name: str, channels: int, classes: int):
    from ultralytics.nn.tasks import DetectionModel

    return DetectionModel(f"{name}.yaml", ch=channels, nc=classes, verbose=False)


def train_step(args):
    """fn() running one training step on the next batch."""
    import numpy as np
    import torch
    from ultralytics.cfg import get_cfg

    data = np.load(args.batches)
    images = torch.from_numpy(np.ascontiguousarray(data["images"].transpose(0, 1, 4, 2, 3)))  # K,B,C,H,W
    classes = int(data["classes"])
    model = _model(args.model, images.shape[2], classes)
    model.args = get_cfg()  # the trainer's default hyperparameters (box 7.5, cls 0.5, dfl 1.5)
    model.train()
    optimizer = torch.optim.SGD(model.parameters(), lr=0.01, momentum=0.937, nesterov=True)
    batches = [_ultralytics_batch(images[k], data["boxes"][k], data["labels"][k], data["mask"][k])
               for k in range(images.shape[0])]
    state = {"k": 0}

    def step():
        batch = batches[state["k"] % len(batches)]
        state["k"] += 1
        loss, _ = model.loss(batch)
        optimizer.zero_grad(set_to_none=True)
        loss.sum().backward()
        optimizer.step()

    return step


def _ultralytics_batch(images, boxes, labels, mask):
    """The trainer's batch dict: image, then one row per box (image index, class, normalised xywh)."""
    import numpy as np
    import torch

    _, _, h, w = images.shape
    index, slot = np.nonzero(mask)
    xyxy = boxes[index, slot].astype(np.float32)
    xywh = np.stack([(xyxy[:, 0] + xyxy[:, 2]) / 2 / w, (xyxy[:, 1] + xyxy[:, 3]) / 2 / h,
                     (xyxy[:, 2] - xyxy[:, 0]) / w, (xyxy[:, 3] - xyxy[:, 1]) / h], axis=1)
    return {"img": images, "batch_idx": torch.from_numpy(index.astype(np.float32)),
            "cls": torch.from_numpy(labels[index, slot].astype(np.float32)[:, None]),
            "bboxes": torch.from_numpy(xywh)}


def forward(args):
    """fn() running the fused, frozen TorchScript network once."""
    import torch

    if args.twin:
        return twin_forward(args.twin, args.twin_layout)
    h, w = (int(v) for v in args.hw.split(","))
    model = _model(args.model, args.channels, args.classes).fuse().eval()
    for module in model.modules():
        if hasattr(module, "export"):  # the head returns its decoded tensor alone, as ultralytics' exporter sets it
            module.export, module.format = True, "torchscript"
    image = torch.randn(1, args.channels, h, w, generator=torch.Generator().manual_seed(0))
    with torch.inference_mode():
        frozen = torch.jit.freeze(torch.jit.trace(model, image, strict=False, check_trace=False))

    def call():
        with torch.inference_mode():
            frozen(image)

    return call


def twin_forward(case: str, layout: str):
    """fn() running the frozen twin of the project network in `case`; fn.check: its exactness."""
    import torch

    from peer_twins import build_checked  # beside this script, which runs with its folder on sys.path

    net, image, check = build_checked(case, layout)

    def call():
        with torch.inference_mode():
            net(image)

    call.check = check
    return call


def serve(fn) -> None:
    """The worker protocol: a ready line (with fn.check where fn has one), then timed calls on request."""
    fn()  # a first call outside the timing (allocation, TorchScript's profiling run)
    print(json.dumps({"ready": True, **({"check": fn.check} if hasattr(fn, "check") else {})}), flush=True)
    for line in sys.stdin:
        if line.strip() in ("", "quit"):
            break
        times = []
        for _ in range(int(line)):
            start = time.perf_counter()
            fn()
            times.append(1e3 * (time.perf_counter() - start))
        print(json.dumps({"ms": times}), flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", choices=("train", "forward"), required=True)
    p.add_argument("--model", default="yolov8n", help="an ultralytics model yaml's name (yolov8n, yolov8s, ...)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--batches", help="train: the lead's batches (.npz)")
    p.add_argument("--hw", default="256,64", help="forward: input height,width")
    p.add_argument("--channels", type=int, default=3)
    p.add_argument("--classes", type=int, default=6)
    p.add_argument("--twin", help="forward: a project network's case (.npz from experiments.twin_export)")
    p.add_argument("--twin-layout", default="channels_last", help="the twin's memory format (peer_twins.LAYOUTS)")
    args = p.parse_args(argv)
    _threads(args.threads)
    with contextlib.redirect_stdout(sys.stderr):  # stdout carries the protocol alone (ultralytics prints banners)
        fn = train_step(args) if args.mode == "train" else forward(args)
    serve(fn)
    return 0


if __name__ == "__main__":
    sys.exit(main())
