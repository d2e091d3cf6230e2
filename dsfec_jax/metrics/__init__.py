"""Detection metrics that judge boxes, whoever made them.

``dsfec_jax.metrics.nuscenes``: the nuScenes detection AP (centre-distance matching, 0.5/1/2/4 m), computed
exactly as nuscenes-devkit 1.2.0 does, plus the official submission JSON format and a CLI
(``python -m dsfec_jax.metrics.nuscenes --gt GT.json --pred PRED.json``).
``dsfec_jax.metrics.resampling``: per-frame match tables and that AP on any resample of the frames
(bootstrap intervals). ``dsfec_jax.metrics.kitti3d``: the View-of-Delft / KITTI 3D AP.
``dsfec_jax.metrics.voc``: the command that scores detection files against VOC XML
(``python -m dsfec_jax.metrics.voc --gt-xml DIR --dets DIR --names voc.names``); ``boxes2d/``: the
2D-box metrics (COCO, DAROD, ultralytics, VOC).

Nothing is re-exported here on purpose: importing the submodule from the package ``__init__`` would make
``python -m dsfec_jax.metrics.nuscenes`` warn that the module was imported before it ran.
"""
