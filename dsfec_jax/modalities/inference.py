"""What the JAX predictors of every modality run: the inference form of the detector they are given.

A predictor is built with a trained detector and its variables (or none yet: training builds one
predictor and assigns `.variables` before each validation). `InferenceVariables` turns the
detector into its zoo.InferenceForm once (the family's deploy form, every BatchNorm folded into its
conv) and every assignment of trained variables into that form's variables, so `.detector` and
`.variables` are always the pair the jitted network runs, on the device (a subclass that calls
`self.network(self.variables, ...)` stays right). Folding is a few elementwise ops per layer, so
re-assigning variables between validations stays cheap. Detectors that are not the zoo's (a NAS
supernet's wrapper) and already folded ones run as they are.

A predictor made for deployment (`constant_weights=True`: api.load, the eval and predict commands,
`dsfec bench`) compiles its weights into the program as constants, as an ONNX graph holds its
initializers. A call then passes the inputs alone (YOLOv8n's 126 weight arrays cost every call a
fixed time to pass: docs/performance.md), and the stride-1 3x3 convs run as Winograd's products from
kernels transformed once while tracing (layers/conv_product.py). The price is a longer first
compile, and a fresh one for each new set of variables, which the persistent compilation cache
cannot serve; so training's validation predictors keep the weights as arguments. Weights over
CONSTANT_WEIGHTS_MAX_BYTES stay arguments too: the program would hold a second copy of them, and
XLA's compile time grows with its constants.
"""

from __future__ import annotations

import jax

from .. import zoo

CONSTANT_WEIGHTS_MAX_BYTES = 64 << 20  # YOLOv8s's 44 MB fits; YOLOv8m/l and Darknet-53 keep arguments


class InferenceVariables:
    """Predictor mixin: in __init__, `self.detector = self._inference_detector(detector)`, then
    `self.variables = variables` (trained; None until known), and build the network on `self.detector`."""

    _form: zoo.InferenceForm | None = None
    _variables: dict | None = None
    constant_weights: bool = False  # the weights compiled into the program (module docstring)
    _with_weights = None  # the jitted network closed over the current variables, made on first call

    def _inference_detector(self, detector):
        """The detector the jitted network runs for the trained `detector`."""
        plain = type(detector) is zoo.Detector  # a subclass (a NAS supernet wrapper) has inputs of its own: as it is
        self._form = zoo.InferenceForm(detector) if plain else None
        return self._form.detector if plain else detector

    @property
    def variables(self) -> dict | None:
        """The variables `self.detector` runs (assign the trained ones: they are converted)."""
        return self._variables

    @variables.setter
    def variables(self, trained: dict | None) -> None:
        convert = trained is not None and self._form is not None
        converted = self._form.variables(trained) if convert else trained
        # on the device once: numpy weights would be converted again on every jitted call
        self._variables = None if converted is None else jax.device_put(converted)
        self._with_weights = None

    def call_network(self, *inputs):
        """`self.network(self.variables, *inputs)`: the predictor's jitted network, with the weights
        compiled in as constants where `constant_weights` is set and they fit."""
        if not self.constant_weights or self._variables is None:
            return self.network(self._variables, *inputs)
        if self._with_weights is None:
            self._with_weights = jit_with_weights(self.network, self._variables)
        return self._with_weights(*inputs)


def jit_with_weights(network, variables):
    """`network` (jitted fn(variables, *inputs)) as fn(*inputs), `variables` compiled into the
    program as constants, or passed as arguments where they exceed CONSTANT_WEIGHTS_MAX_BYTES."""
    if weight_bytes(variables) > CONSTANT_WEIGHTS_MAX_BYTES:
        return lambda *inputs: network(variables, *inputs)
    # the function under the jit: called through the jitted one, the weights would be traced again
    plain = getattr(network, "__wrapped__", network)
    return jax.jit(lambda *inputs: plain(variables, *inputs))


def weight_bytes(variables) -> int:
    """Bytes of every array in `variables` (None: 0)."""
    return sum(leaf.nbytes for leaf in jax.tree_util.tree_leaves(variables))
