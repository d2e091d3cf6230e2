"""The JSON tables of one nuScenes version (`v1.0-*/`), indexed by token, with checked records.

A table file is a JSON list of records, each with a string `token`. The fields the readers use are
checked the first time a record is used (real v1.0-trainval tables hold millions of records; a frame
touches a few dozen), so a corrupt or mistyped table raises ValueError naming the table file, the
record's token and the field, never a KeyError or TypeError from deep inside a reader. A token that
points nowhere names the record and field that hold it. Paths (`sample_data.filename`) must be
relative and stay inside the dataroot.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from ..paths import inside
from ..records import check_fields

# The fields the readers use, per table: kind (records.KINDS) and whether the field is required.
# Optional ones have defaults the readers document (is_key_frame False, prev/next '' = none);
# the devkit's num_lidar_pts / num_radar_pts are optional too (count unknown, box kept).
RECORD_FIELDS = {
    "sample": {"timestamp": ("number", True)},
    "sample_data": {"sample_token": ("token", True), "ego_pose_token": ("token", True),
                    "calibrated_sensor_token": ("token", True), "timestamp": ("number", True),
                    "filename": ("relpath", True), "is_key_frame": ("bool", False), "prev": ("token", False)},
    "ego_pose": {"translation": ("vec3", True), "rotation": ("quat", True)},
    "calibrated_sensor": {"translation": ("vec3", True), "rotation": ("quat", True),
                          "sensor_token": ("token", False)},
    "sensor": {"channel": ("str", True)},
    "sample_annotation": {"sample_token": ("token", True), "translation": ("vec3", True), "size": ("size", True),
                          "rotation": ("quat", True), "prev": ("token", False), "next": ("token", False),
                          "instance_token": ("token", False), "category_name": ("str", False),
                          "num_lidar_pts": ("count", False), "num_radar_pts": ("count", False)},
    "instance": {"category_token": ("token", True)},
    "category": {"name": ("str", True)},
}


class NuScenesTables:
    """The JSON tables of one nuScenes version, indexed by token. Load once, read many frames."""

    TABLES = ("sample", "sample_data", "ego_pose", "calibrated_sensor", "sample_annotation", "instance", "category")

    def __init__(self, dataroot, version: str | None = None):
        self.dataroot = Path(dataroot)
        self.version = version or _only_version(self.dataroot)
        self.tables = {name: self._load(name) for name in self.TABLES}
        self.tables["sensor"] = self._load("sensor") if self.path("sensor").exists() else {}
        self._checked: set[tuple[str, str]] = set()
        self._key_frames = {}
        for sd in self.tables["sample_data"].values():
            if self._is_key_frame(sd):
                self.check("sample_data", sd)
                self._key_frames[sd["sample_token"], self.channel(sd)] = sd
        self._annotations: dict[str, list[dict]] = {}
        for ann in self.tables["sample_annotation"].values():
            check_fields(ann, {"sample_token": RECORD_FIELDS["sample_annotation"]["sample_token"]},
                         self.where("sample_annotation", ann))  # the index key; the rest is checked on use
            self._annotations.setdefault(ann["sample_token"], []).append(ann)

    def path(self, table: str) -> Path:
        return self.dataroot / self.version / f"{table}.json"

    def where(self, table: str, record: dict) -> str:
        return f"{self.path(table)}: record {record['token']!r}"

    def _load(self, name: str) -> dict[str, dict]:
        path = self.path(name)
        try:
            records = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as e:
            raise ValueError(f"{path}: not valid JSON ({type(e).__name__}: {e})") from None
        if not isinstance(records, list):
            raise ValueError(f"{path}: expected a JSON list of records; got {type(records).__name__}")
        for i, r in enumerate(records):
            if not isinstance(r, dict) or not isinstance(r.get("token"), str):
                raise ValueError(f"{path}: record {i}: field 'token' missing; expected an object with a string token")
        return {r["token"]: r for r in records}

    def _is_key_frame(self, sd: dict) -> bool:
        flag = sd.get("is_key_frame", False)
        if not isinstance(flag, bool):
            raise ValueError(f"{self.where('sample_data', sd)}: field 'is_key_frame' = {flag!r}; "
                             f"expected true or false")
        return flag

    def check(self, table: str, record: dict) -> dict:
        """The record, after checking (once) the fields the readers use; ValueError naming file and field."""
        key = (table, record["token"])
        if key not in self._checked:
            check_fields(record, RECORD_FIELDS[table], self.where(table, record))
            self._checked.add(key)
        return record

    def get(self, table: str, token: str, referrer: tuple[str, dict, str] | None = None) -> dict:
        """A checked record by token. `referrer` = (table, record, field) that holds the token, for the error."""
        record = self.tables[table].get(token) if isinstance(token, str) else None
        if record is None:
            if referrer is None:
                raise ValueError(f"{self.path(table)}: no record with token {token!r}")
            ref_table, ref_record, field = referrer
            raise ValueError(f"{self.where(ref_table, ref_record)}: field {field!r} = {token!r} is not a token "
                             f"of {self.path(table).name}")
        return self.check(table, record)

    def follow(self, table: str, record: dict, field: str, target: str) -> dict:
        """The `target` record that `record[field]` (a checked token field of `table`) points to."""
        return self.get(target, record[field], (table, record, field))

    def channel(self, sd: dict) -> str:
        """Sensor channel of a checked sample_data record: via sensor.json, else from the file name."""
        cs = self.tables["calibrated_sensor"].get(sd["calibrated_sensor_token"])
        if cs is not None and self.tables["sensor"]:
            self.check("calibrated_sensor", cs)
            sensor = self.tables["sensor"].get(cs.get("sensor_token", ""))
            if sensor is not None:
                return self.check("sensor", sensor)["channel"]
        match = re.search(r"__([A-Z_]+)__", sd["filename"])
        return match.group(1) if match else ""

    def file(self, sd: dict) -> Path:
        """The data file of a checked sample_data record; FileNotFoundError naming the record if missing."""
        path = inside(self.dataroot, sd["filename"], self.where("sample_data", sd), "filename")
        if not path.is_file():
            raise FileNotFoundError(f"{self.where('sample_data', sd)}: field 'filename' names {path}, "
                                    f"which is not a file (tables without the sensor data?)")
        return path

    def key_frame(self, sample_token: str, channel: str) -> dict | None:
        return self._key_frames.get((sample_token, channel))

    def annotations(self, sample_token: str) -> list[dict]:
        return [self.check("sample_annotation", a) for a in self._annotations.get(sample_token, [])]

    def category_name(self, ann: dict) -> str:
        if "category_name" in ann:  # the devkit adds it in memory; accept tables that already carry it
            return ann["category_name"]
        if "instance_token" not in ann:
            raise ValueError(f"{self.where('sample_annotation', ann)}: field 'instance_token' is missing "
                             f"(and no 'category_name')")
        instance = self.follow("sample_annotation", ann, "instance_token", "instance")
        return self.follow("instance", instance, "category_token", "category")["name"]


def _only_version(dataroot: Path) -> str:
    versions = sorted(p.name for p in dataroot.glob("v1.0-*") if p.is_dir())
    if len(versions) != 1:
        raise FileNotFoundError(f"{dataroot}: expected exactly one v1.0-*/ table folder, found {versions}; "
                                f"pass version=")
    return versions[0]


def list_samples(tables: NuScenesTables) -> list[str]:
    """Sample tokens ordered by timestamp."""
    samples = [tables.check("sample", s) for s in tables.tables["sample"].values()]
    return [s["token"] for s in sorted(samples, key=lambda s: s["timestamp"])]
