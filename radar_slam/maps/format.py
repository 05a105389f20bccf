"""The map on disk: a versioned folder with a checksummed manifest (spec: docs/map_format.md).

    map/
      manifest.json     format name, version, sha256 and size of every other file
      map.json          sessions, image geometry, descriptor settings, GT alignment
      keyframes.npy     one structured row per keyframe (KEYFRAME_DTYPE)
      descriptors.npy   (K, n_theta, n_freq) float16 RaPlace descriptors
      images.bin        the keyframes' PNG images, concatenated (offsets in keyframes.npy)
      edges.npy         the pose graph over the keyframes (EDGE_DTYPE)

Everything written is a pure function of the `Map` (JSON with sorted keys and exact float
text, `.npy` without timestamps, deterministic PNG), so save -> load -> save is byte-identical.
Loading checks the format name, the version and every checksum before parsing anything, and
raises `MapError` with one line naming the folder and the file; then the content is checked
(finite poses, edges between existing keyframes, settings in range). No GTSAM here.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import RadarSlamError
from radar_slam.maps.validate import map_content_problem
from radar_slam.results import PARTIAL_SUFFIX, remove_stale_partials

FORMAT_NAME = "radar-slam-map"
FORMAT_VERSION = 1
MANIFEST_FILE = "manifest.json"
META_FILE = "map.json"
KEYFRAMES_FILE = "keyframes.npy"
DESCRIPTORS_FILE = "descriptors.npy"
IMAGES_FILE = "images.bin"
EDGES_FILE = "edges.npy"
DATA_FILES = (META_FILE, KEYFRAMES_FILE, DESCRIPTORS_FILE, IMAGES_FILE, EDGES_FILE)

KEYFRAME_DTYPE = np.dtype(
    [
        ("session", "<i4"),
        ("scan", "<i8"),
        ("timestamp_ns", "<i8"),
        ("pose", "<f8", (3,)),
        ("gt_pose", "<f8", (3,)),
        ("image_offset", "<i8"),
        ("image_bytes", "<i8"),
        ("image_scale", "<f4"),
    ]
)
"""A keyframe: its session (index into `sessions`), scan index in that session's sequence,
timestamp [ns], optimised pose T_map_radar (x, y [m], yaw [rad]) in the map frame, ground-truth
pose in the sequence's GT frame (NaN without GT; for evaluation only), and where its image lies
in images.bin with the image's intensity scale."""

EDGE_KINDS = ("odometry", "loop", "intersession")
EDGE_DTYPE = np.dtype(
    [
        ("i", "<i8"),
        ("j", "<i8"),
        ("kind", "<i1"),
        ("measurement", "<f8", (3,)),
        ("information", "<f8", (6,)),
    ]
)
"""A pose-graph edge between keyframe indices i and j: kind (index into `EDGE_KINDS`),
measurement T_i^-1 T_j (x, y [m], yaw [rad]), information upper triangle (I11 I12 I13 I22 I23
I33, order x, y, yaw), as in g2o."""


class MapError(RadarSlamError):
    """A map folder that is missing, damaged, foreign or of another version."""


@dataclass(frozen=True)
class Session:
    """One recording the map was built from.

    Attributes:
        sequence: `family/name` of the sequence.
        scans: scans processed.
        first_ns, last_ns: timestamps of its first and last scan [ns].
        joined: how the session was placed in the map frame: "origin" (the map's first session,
            its SLAM frame is the map frame) or "loops" (verified inter-session loops).
    """

    sequence: str
    scans: int
    first_ns: int
    last_ns: int
    joined: str = "origin"


@dataclass(frozen=True)
class Map:
    """A radar map: keyframes with poses, descriptors and images, and their pose graph.

    Attributes:
        keyframes: (K,) `KEYFRAME_DTYPE` rows, in session then time order.
        descriptors: (K, n_theta, n_freq) float16 RaPlace descriptors.
        images: the K keyframe PNGs (`radar_slam.maps.images`).
        edges: (E,) `EDGE_DTYPE` rows.
        sessions: the recordings, indexed by `keyframes["session"]`.
        settings: the settings the keyframes were made with ("image": `ImageGeometry` fields,
            "descriptor": RaPlace `DescriptorConfig` fields, "keyframe_spacing_m"), plain JSON.
        gt_alignment: (3,) SE(2) T_gt_map taking map-frame poses into the ground truth's frame,
            or None when the map's first session had no ground truth.
    """

    keyframes: NDArray[Any]
    descriptors: NDArray[np.float16]
    images: tuple[bytes, ...]
    edges: NDArray[Any]
    sessions: tuple[Session, ...]
    settings: dict[str, Any] = field(default_factory=dict)
    gt_alignment: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.keyframes)

    @property
    def poses(self) -> NDArray[np.float64]:
        """(K, 3) keyframe poses T_map_radar."""
        return np.asarray(self.keyframes["pose"], dtype=np.float64)

    @property
    def gt_poses(self) -> NDArray[np.float64]:
        """(K, 3) keyframe ground truth (NaN where unknown)."""
        return np.asarray(self.keyframes["gt_pose"], dtype=np.float64)

    @classmethod
    def load(cls, path: Path | str) -> Map:
        """Read and verify a map folder (see `read_map`)."""
        return read_map(Path(path))

    def save(self, path: Path | str) -> None:
        """Write the map into a new folder (see `write_map`)."""
        write_map(Path(path), self)


# --------------------------------------------------------------------------- encoding


def _json_bytes(content: dict[str, Any]) -> bytes:
    return (json.dumps(content, indent=1, sort_keys=True, allow_nan=False) + "\n").encode()


def _npy_bytes(array: NDArray[Any]) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()


def _meta(m: Map) -> dict[str, Any]:
    return {
        "sessions": [
            {
                "sequence": s.sequence,
                "scans": s.scans,
                "first_ns": s.first_ns,
                "last_ns": s.last_ns,
                "joined": s.joined,
            }
            for s in m.sessions
        ],
        "settings": m.settings,
        "gt_alignment": None
        if m.gt_alignment is None
        else [float(v) for v in np.asarray(m.gt_alignment, dtype=np.float64)],
    }


def encode_map(m: Map) -> dict[str, bytes]:
    """File name -> content of every file of the map folder, manifest included."""
    keyframes = np.array(m.keyframes, dtype=KEYFRAME_DTYPE)
    offsets = np.cumsum([0] + [len(png) for png in m.images])
    keyframes["image_offset"] = offsets[:-1]
    keyframes["image_bytes"] = np.diff(offsets)
    files = {
        META_FILE: _json_bytes(_meta(m)),
        KEYFRAMES_FILE: _npy_bytes(keyframes),
        DESCRIPTORS_FILE: _npy_bytes(np.asarray(m.descriptors, dtype=np.float16)),
        IMAGES_FILE: b"".join(m.images),
        EDGES_FILE: _npy_bytes(np.array(m.edges, dtype=EDGE_DTYPE)),
    }
    manifest = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "keyframes": len(keyframes),
        "files": {
            name: {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
            for name, data in files.items()
        },
    }
    return {MANIFEST_FILE: _json_bytes(manifest), **files}


def write_map(path: Path, m: Map) -> None:
    """Write `m` into the new folder `path` atomically (a temporary sibling, then a rename).

    Raises:
        MapError: `path` exists, or the files cannot be written.
    """
    path = Path(path)
    if path.exists():
        raise MapError(f"{path}: exists already; a map is written into a new folder")
    if len(m.descriptors) != len(m) or len(m.images) != len(m):
        raise MapError(f"{path}: keyframes, descriptors and images differ in number")
    remove_stale_partials(path.parent, path.name)  # what a killed writer of it left
    partial = path.with_name(f".{path.name}{PARTIAL_SUFFIX}{os.getpid()}")
    try:
        partial.mkdir(parents=True)
        for name, data in encode_map(m).items():
            (partial / name).write_bytes(data)
        partial.rename(path)
    except OSError as exc:
        shutil.rmtree(partial, ignore_errors=True)
        raise MapError(f"{path}: cannot write the map ({exc.strerror})") from None


# --------------------------------------------------------------------------- decoding


def _read_manifest(path: Path) -> dict[str, Any]:
    if not path.is_dir():
        raise MapError(f"{path}: no map folder there")
    try:
        manifest = json.loads((path / MANIFEST_FILE).read_text())
    except FileNotFoundError:
        raise MapError(f"{path}: not a radar-slam map (no {MANIFEST_FILE})") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MapError(f"{path}: {MANIFEST_FILE} is damaged ({exc})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT_NAME:
        raise MapError(f"{path}: {MANIFEST_FILE} is not a {FORMAT_NAME} manifest")
    if manifest.get("version") != FORMAT_VERSION:
        raise MapError(
            f"{path}: map format version {manifest.get('version')!r}, this radar-slam reads "
            f"version {FORMAT_VERSION}"
        )
    return manifest


def _verified_files(path: Path, manifest: dict[str, Any]) -> dict[str, bytes]:
    listed = manifest.get("files")
    if not isinstance(listed, dict) or sorted(listed) != sorted(DATA_FILES):
        raise MapError(f"{path}: {MANIFEST_FILE} does not list the files {', '.join(DATA_FILES)}")
    files = {}
    for name in DATA_FILES:
        try:
            data = (path / name).read_bytes()
        except OSError:
            raise MapError(f"{path}: {name} is missing or unreadable") from None
        entry = listed[name]
        if len(data) != entry.get("bytes") or hashlib.sha256(data).hexdigest() != entry.get(
            "sha256"
        ):
            raise MapError(f"{path}: {name} is damaged (size or sha256 differs from the manifest)")
        files[name] = data
    return files


def _npy(path: Path, name: str, data: bytes, dtype: np.dtype[Any] | None) -> NDArray[Any]:
    try:
        array = np.load(io.BytesIO(data), allow_pickle=False)
    except ValueError as exc:
        raise MapError(f"{path}: {name} is not a valid .npy file ({exc})") from None
    if dtype is not None and array.dtype != dtype:
        raise MapError(f"{path}: {name} has dtype {array.dtype}, expected {dtype}")
    return array


def _sessions(path: Path, meta: dict[str, Any]) -> tuple[Session, ...]:
    try:
        return tuple(
            Session(
                sequence=str(s["sequence"]),
                scans=int(s["scans"]),
                first_ns=int(s["first_ns"]),
                last_ns=int(s["last_ns"]),
                joined=str(s["joined"]),
            )
            for s in meta["sessions"]
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise MapError(f"{path}: {META_FILE}: bad sessions entry ({exc})") from None


def read_map(path: Path) -> Map:
    """Read a map folder written by `write_map`, verifying version and checksums first, then
    the content (`radar_slam.maps.validate`).

    Raises:
        MapError: missing, foreign, damaged or inconsistent folder (one line naming the file).
    """
    path = Path(path)
    files = _verified_files(path, _read_manifest(path))
    meta = json.loads(files[META_FILE])
    keyframes = _npy(path, KEYFRAMES_FILE, files[KEYFRAMES_FILE], KEYFRAME_DTYPE)
    descriptors = _npy(path, DESCRIPTORS_FILE, files[DESCRIPTORS_FILE], np.dtype(np.float16))
    edges = _npy(path, EDGES_FILE, files[EDGES_FILE], EDGE_DTYPE)
    blob = files[IMAGES_FILE]
    ends = keyframes["image_offset"] + keyframes["image_bytes"]
    if len(descriptors) != len(keyframes) or (len(ends) and int(ends.max()) > len(blob)):
        raise MapError(f"{path}: keyframes.npy does not match descriptors.npy / images.bin")
    sessions = _sessions(path, meta)
    if len(keyframes) and not 0 <= int(keyframes["session"].max()) < len(sessions):
        raise MapError(f"{path}: keyframes.npy refers to a session {META_FILE} does not list")
    images = tuple(
        blob[int(o) : int(o) + int(n)]
        for o, n in zip(keyframes["image_offset"], keyframes["image_bytes"], strict=True)
    )
    alignment = meta.get("gt_alignment")
    loaded = Map(
        keyframes=keyframes,
        descriptors=descriptors,
        images=images,
        edges=edges,
        sessions=sessions,
        settings=dict(meta.get("settings", {})),
        gt_alignment=None if alignment is None else np.asarray(alignment, dtype=np.float64),
    )
    problem = map_content_problem(loaded, len(EDGE_KINDS))
    if problem is not None:
        raise MapError(f"{path}: {problem}")
    return loaded


def map_bytes(path: Path) -> int:
    """Total size of a map folder's files [bytes]."""
    return sum(f.stat().st_size for f in Path(path).iterdir() if f.is_file())
