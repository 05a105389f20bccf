"""Content checks of a loaded map: a map whose checksums were rewritten after damage must still
be refused with one line naming the file and the key, before it is used.

Checked: keyframe poses finite (ground truth finite or NaN, never infinite), descriptors finite,
every edge between two distinct existing keyframes with a finite measurement and information,
the GT alignment finite, and the settings in range (`keyframe_spacing_m` > 0, the image geometry
and the descriptor settings as their config classes check them).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from radar_slam.config import merge
from radar_slam.errors import ConfigError
from radar_slam.maps.images import ImageGeometry
from raplace import DescriptorConfig, checks

if TYPE_CHECKING:
    from radar_slam.maps.format import Map

KEYFRAMES_FILE = "keyframes.npy"
EDGES_FILE = "edges.npy"
DESCRIPTORS_FILE = "descriptors.npy"
META_FILE = "map.json"


def map_content_problem(m: Map, edge_kinds: int) -> str | None:
    """What is wrong with `m` (one line naming the file and the key), or None when it is sound.

    Args:
        m: the loaded map.
        edge_kinds: how many edge kinds there are (`kind` indexes them).
    """
    return _keyframe_problem(m) or _edge_problem(m, edge_kinds) or _meta_problem(m)


def _first(mask: Any) -> int:
    return int(np.flatnonzero(mask)[0])


def _keyframe_problem(m: Map) -> str | None:
    bad = ~np.isfinite(m.poses).all(axis=1)
    if bad.any():
        return f"{KEYFRAMES_FILE}: keyframe {_first(bad)} has a non-finite pose"
    bad = np.isinf(m.gt_poses).any(axis=1)
    if bad.any():
        return f"{KEYFRAMES_FILE}: keyframe {_first(bad)} has an infinite gt_pose"
    descriptors = np.asarray(m.descriptors, dtype=np.float32)
    bad = ~np.isfinite(descriptors.reshape(len(descriptors), -1)).all(axis=1)
    if bad.any():
        return f"{DESCRIPTORS_FILE}: descriptor {_first(bad)} is not finite"
    return None


def _edge_problem(m: Map, edge_kinds: int) -> str | None:
    edges = m.edges
    if not len(edges):
        return None
    i, j = edges["i"], edges["j"]
    outside = (i < 0) | (i >= len(m)) | (j < 0) | (j >= len(m)) | (i == j)
    if outside.any():
        k = _first(outside)
        return (
            f"{EDGES_FILE}: edge {k} joins keyframes {int(i[k])} and {int(j[k])}; the map has "
            f"keyframes 0 to {len(m) - 1}"
        )
    bad = (edges["kind"] < 0) | (edges["kind"] >= edge_kinds)
    if bad.any():
        return f"{EDGES_FILE}: edge {_first(bad)} has an unknown kind"
    values = np.hstack([edges["measurement"], edges["information"]])
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        return f"{EDGES_FILE}: edge {_first(bad)} has a non-finite measurement or information"
    return None


def _meta_problem(m: Map) -> str | None:
    alignment = m.gt_alignment
    if alignment is not None and (alignment.shape != (3,) or not np.isfinite(alignment).all()):
        return f"{META_FILE}: gt_alignment must be three finite numbers"
    settings = m.settings
    try:
        if "keyframe_spacing_m" in settings:
            checks.positive("settings.keyframe_spacing_m", settings["keyframe_spacing_m"])
        merge(
            ImageGeometry,
            ImageGeometry(),
            _section(settings, "image"),
            META_FILE,
            ("settings", "image"),
        )
        descriptor = _section(settings, "descriptor")
        if descriptor:
            merge(
                DescriptorConfig,
                DescriptorConfig(),
                descriptor,
                META_FILE,
                ("settings", "descriptor"),
            )
    except ValueError as exc:
        return f"{META_FILE}: {exc}"
    except ConfigError as exc:
        return str(exc)
    return None


def _section(settings: dict[str, Any], name: str) -> dict[str, Any]:
    section = settings.get(name, {})
    if not isinstance(section, dict):
        raise ValueError(f"settings.{name}: expected a mapping, got {section!r}")
    return section
