"""A morph as one animated glTF 2.0 file (``.glb``): the source mesh with one morph target
per step and an animation of the targets' weights over time.

Blender (File > Import > glTF 2.0: one shape key per step, played by the timeline) and
three.js (``GLTFLoader``: ``mesh.morphTargetInfluences`` driven by an ``AnimationMixer``)
open it as it is. The file follows the glTF 2.0 specification (Khronos): one binary
buffer in the GLB container, float32 positions and displacements with the ``min``/``max``
the specification requires of them, ``uint32`` triangle indices, and the animation's
keyframe ``k`` at time ``k / fps`` whose weights are 1 for target ``k`` (step ``k``) and
0 for the others, interpolated linearly: the shape moves through the steps as it did in
time. Written with numpy and the standard library (no glTF library needed).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from ..version import __version__
from .atomic import atomic_write

__all__ = ["FPS", "write_gltf"]

FPS = 24.0  # steps shown per second of the animation: a film's frame rate

_FLOAT, _UINT = 5126, 5125  # accessor component types (glTF 2.0 §3.6.2)
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963  # bufferView targets
_POINTS, _LINES, _LINE_LOOP, _LINE_STRIP, _TRIANGLES = 0, 1, 2, 3, 4  # primitive modes
_JSON_CHUNK, _BIN_CHUNK = 0x4E4F534A, 0x004E4942  # GLB chunk types


def write_gltf(morph, path, *, fps: float = FPS, name: str = "morph") -> Path:
    """Write a morph as one binary glTF 2.0 file with morph targets (see the module).

    Step 0 (the source) is the mesh's positions; target ``j - 1`` holds the displacement
    ``shapes[j] - shapes[0]`` of step ``j`` (j = 1..T). Surfaces are triangles, a contour
    a line loop (closed) or strip, several contours lines (their segments, each contour
    its own loop), point clouds points; 2D shapes lie in z = 0.

    Parameters
    ----------
    morph : Morph
        A morph result (``shapes`` (T+1, m, d) and ``source``, whose topology is used).
    path : str or Path
        The ``.glb`` file to write (atomically).
    fps : float, optional
        Steps per second of the animation.
    name : str, optional
        Name of the mesh and its node.

    Returns
    -------
    Path
    """
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps!r}")
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    if shapes.shape[2] == 2:
        shapes = np.pad(shapes, ((0, 0), (0, 0), (0, 1)))
    doc, blob = _document(shapes, morph.source, fps, name)
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_bytes(_glb(doc, blob))
    return path


class _Buffer:
    """The binary buffer, its bufferViews and accessors, built one array at a time."""

    def __init__(self):
        self.parts, self.length = [], 0
        self.views, self.accessors = [], []

    def add(self, array: np.ndarray, kind: str, *, target=None, bounds=False) -> int:
        """Append ``array`` (float32 or uint32, (count,) or (count, k)) as one bufferView
        and one accessor; returns the accessor's index."""
        data = np.ascontiguousarray(array).tobytes()
        view = {"buffer": 0, "byteOffset": self.length, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.views.append(view)
        pad = -len(data) % 4  # every bufferView starts 4-byte aligned
        self.parts.append(data + b"\0" * pad)
        self.length += len(data) + pad
        accessor = {"bufferView": len(self.views) - 1, "count": len(array), "type": kind,
                    "componentType": _UINT if array.dtype == np.uint32 else _FLOAT}
        if bounds:  # required of POSITION attributes and animation inputs
            flat = array.reshape(len(array), -1)
            accessor["min"] = flat.min(axis=0).tolist()
            accessor["max"] = flat.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1


def _document(shapes: np.ndarray, source, fps: float, name: str) -> tuple[dict, bytes]:
    """The glTF JSON and its binary buffer."""
    steps = len(shapes) - 1
    buf = _Buffer()
    base = shapes[0].astype(np.float32)
    primitive = {"attributes": {"POSITION": buf.add(base, "VEC3", target=_ARRAY_BUFFER,
                                                    bounds=True)}}
    primitive["mode"] = _mode(source)
    if primitive["mode"] in (_TRIANGLES, _LINES):
        pairs = source.faces if primitive["mode"] == _TRIANGLES else source.edges
        indices = np.asarray(pairs, dtype=np.uint32).reshape(-1)
        primitive["indices"] = buf.add(indices, "SCALAR", target=_ELEMENT_ARRAY_BUFFER)
    mesh = {"name": name, "primitives": [primitive]}
    doc = {"asset": {"version": "2.0", "generator": f"modalmorph {__version__}"},
           "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"name": name, "mesh": 0}], "meshes": [mesh]}
    if steps:  # glTF allows no empty list of targets or weights
        primitive["targets"] = [
            {"POSITION": buf.add((shapes[j] - shapes[0]).astype(np.float32), "VEC3",
                                 target=_ARRAY_BUFFER, bounds=True)}
            for j in range(1, steps + 1)]
        mesh["weights"] = [0.0] * steps
        mesh["extras"] = {"targetNames": [f"step {j}" for j in range(1, steps + 1)]}
        times = (np.arange(steps + 1) / fps).astype(np.float32)
        weights = np.eye(steps + 1, steps, k=-1, dtype=np.float32)  # key k: target k - 1
        sampler = {"input": buf.add(times, "SCALAR", bounds=True),
                   "output": buf.add(weights.reshape(-1), "SCALAR"),
                   "interpolation": "LINEAR"}
        doc["animations"] = [{"name": name, "samplers": [sampler], "channels": [
            {"sampler": 0, "target": {"node": 0, "path": "weights"}}]}]
    doc["buffers"] = [{"byteLength": buf.length}]
    doc["bufferViews"], doc["accessors"] = buf.views, buf.accessors
    return doc, b"".join(buf.parts)


def _mode(source) -> int:
    """The primitive mode of the source's topology."""
    if source.has_faces:
        return _TRIANGLES
    if source.ordered and len(source.sizes) > 1:
        return _LINES  # several contours: no segment from one to the next
    if source.ordered:
        return _LINE_LOOP if source.closed else _LINE_STRIP
    return _POINTS


def _glb(doc: dict, blob: bytes) -> bytes:
    """The GLB container: a 12-byte header, the JSON chunk (padded with spaces) and the
    binary chunk (padded with zeros)."""
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return b"".join([struct.pack("<4sII", b"glTF", 2, total),
                     struct.pack("<II", len(text), _JSON_CHUNK), text,
                     struct.pack("<II", len(blob), _BIN_CHUNK), blob])
