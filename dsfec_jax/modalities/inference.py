"""What the JAX predictors of every modality run: the inference form of the detector they are given.

A predictor is built with a trained detector and its variables (or none yet: training builds one
predictor and sets `.variables` before each validation). `InferenceVariables` keeps `variables`
as given and, on every assignment, computes `inference_variables`: the zoo's InferenceForm of
them (the family's deploy form, every BatchNorm folded into its conv), which the jitted network
runs. Folding is a few elementwise ops per layer, so re-assigning variables stays cheap. Detectors
that are not the zoo's (a NAS supernet's wrapper) and already folded ones run as they are.
"""

from __future__ import annotations

from .. import zoo


class InferenceVariables:
    """Predictor mixin: call `_inference_detector(detector)` in __init__ (before setting
    `self.variables`) and build the network on the detector it returns."""

    _form: zoo.InferenceForm | None = None
    _variables: dict | None = None
    inference_variables: dict | None = None

    def _inference_detector(self, detector):
        """The detector the jitted network should run for `detector`."""
        plain = isinstance(detector, zoo.Detector) and not isinstance(detector, zoo.FoldedDetector)
        self._form = zoo.InferenceForm(detector) if plain else None
        return self._form.detector if plain else detector

    @property
    def variables(self) -> dict | None:
        """The variables as given (trained form)."""
        return self._variables

    @variables.setter
    def variables(self, variables: dict | None) -> None:
        self._variables = variables
        fold = variables is not None and self._form is not None
        self.inference_variables = self._form.variables(variables) if fold else variables
