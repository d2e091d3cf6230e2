"""One folder per modality's pipeline (points/, rd/, image/): how one kind of input flows from a
source to boxes and scores. `base.Modality` is the record of the verbs a modality supplies;
`registry.modality_of(cfg)` finds a config's. train/, deploy/ and profile/ stay modality-free: they
take the record's verbs as arguments and never import this room."""
