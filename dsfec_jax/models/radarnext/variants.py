"""The named RadarNeXt-family variants (arXiv 2501.02314, Tables I-II) as data."""

from __future__ import annotations

from .net import RadarNeXtConfig, for_tj4d

# RadarNeXt (arXiv 2501.02314) Tables I-II: three necks, each over Rep-DWC or the Dense backbone.
RADARNEXT_NOTE = "VoD grid 320x320, 0.16 m pillars; counts after re-parameterization, corner head excluded"
RADARNEXT_VARIANTS: dict[str, RadarNeXtConfig] = {}
for _neck, _dcn in (("fpn", ()), ("pan", ()), ("mdfen", (4,))):
    RADARNEXT_VARIANTS[f"radarnext_{_neck}"] = RadarNeXtConfig(
        name=f"radarnext_{_neck}", neck=_neck, dcn_positions=_dcn, notes=RADARNEXT_NOTE)
    RADARNEXT_VARIANTS[f"radarnext_{_neck}_dense"] = RadarNeXtConfig(
        name=f"radarnext_{_neck}_dense", neck=_neck, dcn_positions=_dcn, backbone="dense",
        notes="Dense = the PointPillars SECOND backbone (3x3 convs, 1 + (3,5,5) per stage). " + RADARNEXT_NOTE)
for _neck in ("fpn", "pan", "mdfen"):  # Table I's TJ4D column: the Rep-DWC variants on TJ4DRadSet
    RADARNEXT_VARIANTS[f"radarnext_{_neck}_tj4d"] = for_tj4d(RADARNEXT_VARIANTS[f"radarnext_{_neck}"],
                                                            f"radarnext_{_neck}_tj4d")
