"""What the JAX predictors of every modality run: the inference form of the detector they are given.

A predictor is built with a trained detector and its variables (or none yet: training builds one
predictor and assigns `.variables` before each validation). `InferenceVariables` turns the
detector into its zoo.InferenceForm once (the family's deploy form, every BatchNorm folded into its
conv) and every assignment of trained variables into that form's variables, so `.detector` and
`.variables` are always the pair the jitted network runs, on the device (a subclass that calls
`self.network(self.variables, ...)` stays right). Folding is a few elementwise ops per layer, so
re-assigning variables between validations stays cheap. Detectors that are not the zoo's (a NAS
supernet's wrapper) and already folded ones run as they are.
"""

from __future__ import annotations

import jax

from .. import zoo


class InferenceVariables:
    """Predictor mixin: in __init__, `self.detector = self._inference_detector(detector)`, then
    `self.variables = variables` (trained; None until known), and build the network on `self.detector`."""

    _form: zoo.InferenceForm | None = None
    _variables: dict | None = None

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
