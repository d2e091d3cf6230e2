"""A user's own radar captures as an RD model's input (modalities/files.py reads the PATHs); both are
`.npy`, told apart by their dtype (read from the header before any data):

- a range-Doppler map: real float, shape RD_MAP_SHAPE (256 range rows near -> far, 64 Doppler
  columns slow -> fast after fftshift: the RADDet sensor's grid, which the synthetic benchmark and
  the models are built on), holding log10(|X|^2 + 1) power as the simulator writes it. Its axes in
  metres and m/s are the RADDet sensor's (data/rd/sensor.RADDET_SENSOR: 0.1953 m, 0.41968 m/s a cell).
- a raw TI ADC capture: complex, the OpenRadar tutorial's layouts ((chirps, samples) or (chirps,
  channels, samples) of 16-bit words; data/rd/ti_adc.CAPTURES), processed into a map by the same
  chain as the tutorial sample (data/rd/processing.adc_to_rd) with that radar's axes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...boxes.boxes2d import Boxes2D
from ...data.rd.figure import edge_values
from ...data.rd.npy_file import npy_header, read_npy
from ...data.rd.processing import adc_to_rd
from ...data.rd.sample import RDAxes, RDSample
from ...data.rd.sensor import RADDET_SENSOR
from ...data.rd.ti_adc import CAPTURES, read_ti_adc
from ..files import FileReader, InputFileError, fail

RD_MAP_SHAPE = (RADDET_SENSOR.num_samples, RADDET_SENSOR.num_chirps)
ADC_SENSORS = {shape: sensor for shape, sensor in CAPTURES.values()}  # stored shape -> its radar
SOURCE = "file"


def read_sample(path: Path, cfg=None, columns: str | None = None) -> RDSample:
    """One .npy as an RDSample (no boxes), id = the path; InputFileError naming the file."""
    if columns is not None:
        raise InputFileError(f"--columns applies to point-cloud files; {path} is a range-Doppler input")
    try:
        shape, dtype = npy_header(path)
        if dtype.kind == "c":
            return _adc_sample(path, shape)
        return _map_sample(path)
    except InputFileError:
        raise
    except ValueError as err:  # the readers' messages name the file
        raise InputFileError(str(err)) from None


def _map_sample(path: Path) -> RDSample:
    power = read_npy(path, "range-Doppler map (range rows, Doppler columns) of log10 power", "f", RD_MAP_SHAPE)
    if not np.isfinite(power).all():
        raise fail(path, f"{int((~np.isfinite(power)).sum())} map cells hold NaN or infinity")
    return RDSample(power.astype(np.float32), RDAxes.of_sensor(RADDET_SENSOR), Boxes2D.empty(), RADDET_SENSOR,
                    "log10", sample_id=str(path), source=SOURCE)


def _adc_sample(path: Path, shape: tuple[int, ...]) -> RDSample:
    if shape not in ADC_SENSORS:
        raise fail(path, f"complex array of shape {shape}: a raw TI ADC capture must be one of "
                         f"{sorted(ADC_SENSORS)} (chirps, [channels,] samples); a range-Doppler map is real")
    adc, sensor = read_ti_adc(path, ADC_SENSORS[shape])
    power, scale = adc_to_rd(adc, sensor)
    return RDSample(power, RDAxes.of_sensor(sensor), Boxes2D.empty(), sensor, scale, sample_id=str(path),
                    source=SOURCE, meta={"adc_shape": list(shape)})


def entry(sample: RDSample, found: Boxes2D) -> dict:
    """A sample's detections: the box in map cells (x = Doppler column, y = range row, edges) and
    in physical units (range in m, radial velocity in m/s, negative = approaching)."""
    r, v = sample.axes.range_m, sample.axes.velocity_mps
    return {"map_shape": list(sample.shape),
            "detections": [{"class": str(n), "score": round(float(s), 5),
                            "box_cells": [round(float(c), 2) for c in xyxy],
                            "range_m": [round(float(e), 3) for e in edge_values(r, xyxy[[1, 3]])],
                            "velocity_mps": [round(float(e), 3) for e in edge_values(v, xyxy[[0, 2]])]}
                           for n, s, xyxy in zip(found.names, found.scores, found.xyxy)]}


READER = FileReader(suffixes=(".npy",), read=read_sample, entry=entry, ident=lambda sample: sample.sample_id,
                    kinds=f"range-Doppler maps ({RD_MAP_SHAPE[0]} x {RD_MAP_SHAPE[1]} float .npy) and raw TI ADC "
                          "captures (complex .npy)")
