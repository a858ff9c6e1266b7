"""A generated corpus of malformed shape files, for every reader and the command line.

``write_corpus(folder)`` writes, for every supported extension, a small valid file and
many broken variants of it: truncations, header-only files, random bytes and bit flips,
absurd counts, non-finite and huge numbers, wrong types and shapes, deep nesting, other
formats under the extension, and the odd-but-valid cases (a mesh without faces, 2D points
with faces). Deterministic for a given seed.

Run as a script to check the command line on every file, each as a separate process::

    PYTHONPATH=src python tests/fuzz_corpus.py /tmp/corpus

It prints one line per failing file and the counts; a failure is a run that takes more than
30 s, exits other than 0 or 2, prints a traceback, prints more than one line on stderr when
it exits 2, or leaves anything in its working folder but the two inputs and a complete
output folder (exit 0).
"""

from __future__ import annotations

import contextlib
import io
import json
import struct
import sys
from pathlib import Path

import numpy as np

# A 2D contour (12 nodes) and a 3D surface (an octahedron) that every base file holds.
_ANGLES = np.linspace(0, 2 * np.pi, 12, endpoint=False)
CONTOUR = np.c_[np.cos(_ANGLES), 0.6 * np.sin(_ANGLES)] * 10.0
OCTA_POINTS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                       dtype=np.float64)
OCTA_FACES = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5],
                       [3, 1, 5], [0, 3, 5]])
_MESH_EXTS = (".ply", ".obj", ".stl", ".off", ".vtk", ".vtu", ".msh", ".mesh")
_IMAGE_EXTS = (".png", ".tif", ".jpg", ".bmp", ".gif")


def _text(points, sep=",", header=True) -> bytes:
    lines = [sep.join("xyz"[: points.shape[1]])] if header else []
    lines += [sep.join(repr(float(v)) for v in row) for row in points]
    return ("\n".join(lines) + "\n").encode()


def _npy(array) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    return buf.getvalue()


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _svg(body: str) -> bytes:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100">{body}'
            f'</svg>').encode()


def _image(ext: str, array) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(array).save(buf, format={".tif": "TIFF", ".jpg": "JPEG"}.get(
        ext, ext[1:].upper()))
    return buf.getvalue()


def _mask(size=40) -> np.ndarray:
    yy, xx = np.mgrid[:size, :size]
    return (((xx - size / 2) ** 2 + (yy - size / 2) ** 2) < (size / 3) ** 2).astype(
        np.uint8) * 255


def _nifti(ext: str, array, zero_spacing: bool = False) -> bytes:
    """A NIfTI-1 file's bytes (gzipped for .nii.gz) holding ``array`` (X, Y[, ...]), pixel
    spacing 1.5 (or a header saying 0 for the first axis)."""
    import gzip

    import nibabel

    image = nibabel.Nifti1Image(array, np.diag([1.5, 1.5, 1.0, 1.0]))
    data = bytearray(image.to_bytes())
    if zero_spacing:
        data[80:84] = struct.pack("<f", 0.0)  # pixdim[1], after dim (40) and 6 fields
    return gzip.compress(bytes(data), mtime=0) if ext == ".nii.gz" else bytes(data)


def _nifti_cases(ext: str) -> dict[str, bytes]:
    ring = (_mask() > 0).astype(np.uint8) * 2
    ring[15:25, 15:25] = 1
    return {
        "blank": _nifti(ext, np.zeros((20, 20), np.uint8)),
        "labels": _nifti(ext, ring),  # a label image without --label: refused, named
        "volume": _nifti(ext, np.zeros((8, 8, 3, 2), np.uint8)),  # 3D+t: refused
        "frames": _nifti(ext, np.stack([_mask()] * 3, axis=-1)[:, :, None]),  # 2D+t
        "stack": _nifti(ext, np.stack([_mask()] * 3, axis=-1)),  # 3D: a surface
        "zero_spacing": _nifti(ext, _mask(), zero_spacing=True),
        "nan": _nifti(ext, np.where(_mask() > 0, np.nan, 0.0).astype(np.float32)),
        "one_pixel": _nifti(ext, np.ones((1, 1), np.uint8)),
    }


def _mesh(ext: str, points=OCTA_POINTS, faces=OCTA_FACES, fmt=None) -> bytes:
    import meshio

    cells = [("triangle", faces)] if faces is not None else [("vertex", np.arange(
        len(points))[:, None])]
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"m{ext}"
        kw = {"binary": False} if ext in (".ply", ".stl", ".vtk") else {}
        said = io.StringIO()  # meshio's notes on the format
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            meshio.write(path, meshio.Mesh(points, cells), file_format=fmt, **kw)
        return path.read_bytes()


def _mutations(data: bytes, rng) -> dict[str, bytes]:
    """Generic damage to a file's bytes."""
    n = len(data)
    out = {"one_byte": data[:1], "header_line": data.split(b"\n")[0] + b"\n"}
    for frac in (0.1, 0.25, 0.5, 0.75, 0.9):
        out[f"cut{int(frac * 100)}"] = data[: max(1, int(n * frac))]
    out["cut_last"] = data[:-1] if n > 1 else b"\0"
    out["random"] = rng.bytes(max(n, 8))
    out["zeros"] = bytes(max(n, 8))
    for k in range(4):
        flipped = bytearray(data)
        for pos in rng.integers(0, n, size=1 + 2 * k):
            flipped[pos] ^= 1 << int(rng.integers(0, 8))
        out[f"flip{k}"] = bytes(flipped)
    shuffled = bytearray(data)
    start = int(rng.integers(0, max(1, n - 16)))
    shuffled[start:start + 16] = rng.bytes(min(16, n - start))
    out["garbled16"] = bytes(shuffled)
    out["html"] = b"<!DOCTYPE html><html><body><p>Not found</p></body></html>\n"
    out["utf16"] = data.decode("latin-1").encode("utf-16")
    out["doubled"] = data + data
    out["garbage_tail"] = data + rng.bytes(64)
    return out


def _text_cases(points2, points3) -> dict[str, bytes]:
    """Broken and odd text tables (CSV-like, for .csv, .tsv and .txt)."""
    good = _text(points2)
    return {
        "header_only": b"x,y\n",
        "nan": good.replace(b"10.0", b"nan", 1),
        "inf": good.replace(b"10.0", b"inf", 1),
        "huge": good.replace(b"10.0", b"1e400", 1),
        "big_int": good.replace(b"10.0", b"9" * 400, 1),
        "tiny": _text(points2 * 1e-300),
        "one_column": b"x\n1\n2\n3\n4\n",
        "four_columns": b"1,2,3,4\n5,6,7,8\n9,1,2,3\n4,5,6,7\n",
        "ragged": b"1,2\n3,4,5\n6,7\n",
        "letters": b"1,2\n3,a\n5,6\n",
        "duplicates": _text(np.vstack([points2[:3]] * 3)),
        "collinear": _text(np.c_[np.arange(10.0), np.zeros(10)]),
        "one_point": b"1,2\n",
        "three_d": _text(points3),
        "blank_lines": b"\n\n\n",
        "comments_only": b"# x,y\n# 1,2\n",
        "semicolon_decimal_comma": b"x;y\n1,5;2\n3;4,5\n5;1\n",
        "bom": b"\xef\xbb\xbf" + good,
        "nul_bytes": good.replace(b"\n", b"\0", 3),
        "long_line": b"1," * 100000 + b"2\n",
        "xyz_header_missing_y": b"x,z\n1,2\n3,4\n5,6\n",
        "crlf": good.replace(b"\n", b"\r\n"),
        "quoted": b'"x","y"\n"1","2"\n"3","4"\n"5","1"\n',
    }


def _npy_cases(rng) -> dict[str, bytes]:
    pickled = np.empty(3, dtype=object)
    pickled[:] = [1, "a", None]
    header = _npy(CONTOUR)
    return {
        "scalar": _npy(np.float64(3.0)),
        "zero_d_int": _npy(np.int64(7)),
        "one_column": _npy(CONTOUR[:, :1]),
        "one_d": _npy(CONTOUR[:, 0]),
        "three_d_array": _npy(np.zeros((2, 3, 4))),
        "empty": _npy(np.zeros((0, 2))),
        "object": _npy(pickled),
        "complex": _npy(CONTOUR.astype(complex)),
        "bool": _npy(np.ones((5, 2), dtype=bool)),
        "strings": _npy(np.array([["a", "b"]] * 4)),
        "nan": _npy(np.where(np.arange(24).reshape(12, 2) == 5, np.nan, CONTOUR)),
        "inf": _npy(np.full((4, 2), np.inf)),
        "float16_huge": _npy(np.array([[6e4, 0], [0, 6e4], [-6e4, 0]], dtype=np.float16)),
        "int_huge": _npy(np.array([[2**62, 0], [0, 2**62], [-(2**62), 5]], dtype=np.int64)),
        "uint8": _npy((CONTOUR + 20).astype(np.uint8)),
        "fortran": _npy(np.asfortranarray(CONTOUR)),
        "big_endian": _npy(CONTOUR.astype(">f8")),
        "structured": _npy(np.zeros(4, dtype=[("x", "f8"), ("y", "f8")])),
        "absurd_shape": header.replace(b"(12, 2)", b"(999999999999, 2)"),
        "negative_shape": header.replace(b"(12, 2)", b"(-12, 2)"),
        "bad_dtype": header.replace(b"'<f8'", b"'<q9'"),
        "duplicates": _npy(np.vstack([CONTOUR[:4]] * 3)),
        "collinear": _npy(np.c_[np.arange(10.0), np.arange(10.0)]),
        "huge_coords": _npy(CONTOUR * 1e305),
        "tiny_coords": _npy(CONTOUR * 1e-305),
        "three_d_points": _npy(OCTA_POINTS),
        "random_floats": _npy(rng.standard_normal((50, 2))),
    }


def _npz_cases() -> dict[str, bytes]:
    good = _npz(points=OCTA_POINTS, faces=OCTA_FACES)
    return {
        "no_points_two_arrays": _npz(a=CONTOUR, b=CONTOUR),
        "empty_archive": _npz(),
        "points_scalar": _npz(points=np.float64(1.0)),
        "points_object": _npz(points=np.array([1, "a"], dtype=object)),
        "faces_2d_points": _npz(points=CONTOUR, faces=np.array([[0, 1, 2], [2, 3, 4]])),
        "faces_float": _npz(points=OCTA_POINTS, faces=OCTA_FACES.astype(float)),
        "faces_out_of_range": _npz(points=OCTA_POINTS, faces=OCTA_FACES + 10),
        "faces_negative": _npz(points=OCTA_POINTS, faces=OCTA_FACES - 3),
        "faces_quads": _npz(points=OCTA_POINTS, faces=np.zeros((2, 4), dtype=int)),
        "faces_empty": _npz(points=OCTA_POINTS, faces=np.zeros((0, 3), dtype=int)),
        "closed_array": _npz(points=CONTOUR, closed=np.array([1, 0, 1])),
        "closed_string": _npz(points=CONTOUR, closed=np.array("yes")),
        "half": good[: len(good) // 2],
        "nan_points": _npz(points=np.full((4, 3), np.nan)),
        "points_3d_no_faces": _npz(points=OCTA_POINTS),
        "contour": _npz(points=CONTOUR, closed=np.bool_(False)),
        "degenerate_faces": _npz(points=OCTA_POINTS, faces=np.zeros((8, 3), dtype=int)),
    }


def _json_cases() -> dict[str, bytes]:
    pts = CONTOUR.tolist()
    dump = lambda obj: json.dumps(obj).encode()  # noqa: E731
    return {
        "deep": b"[" * 100000 + b"]" * 100000,
        "deep_object": b'{"points":' + b"[" * 5000 + b"]" * 5000 + b"}",
        "big_int": dump([[10 ** 400, 1], [2, 3], [4, 5]]),
        "huge_float": b"[[1e400, 1], [2, 3], [4, 5]]",
        "nan_literal": b"[[NaN, 1], [2, 3], [4, 5]]",
        "infinity_literal": b"[[Infinity, 1], [2, 3], [4, -Infinity]]",
        "scalar": b"3",
        "string": b'"points"',
        "null": b"null",
        "empty_list": b"[]",
        "empty_object": b"{}",
        "flat_list": dump(CONTOUR.ravel().tolist()),
        "ragged": b"[[1, 2], [3, 4, 5], [6, 7]]",
        "strings": b'[["1", "2"], ["3", "4"], ["5", "6"]]',
        "bools": b"[[true, false], [false, true], [true, true]]",
        "nested_too_deep": b"[[[1, 2]], [[3, 4]], [[5, 6]]]",
        "one_column": b"[[1], [2], [3], [4]]",
        "points_null": b'{"points": null}',
        "points_dict": b'{"points": {"x": 1}}',
        "closed_string": dump({"points": pts, "closed": "yes"}),
        "faces_2d": dump({"points": pts, "faces": [[0, 1, 2], [2, 3, 4]]}),
        "faces_floats": dump({"points": OCTA_POINTS.tolist(), "faces": [[0.5, 1, 2]]}),
        "faces_strings": dump({"points": OCTA_POINTS.tolist(), "faces": [["a", 1, 2]]}),
        "faces_ragged": dump({"points": OCTA_POINTS.tolist(), "faces": [[0, 1], [1, 2, 3]]}),
        "faces_out_of_range": dump({"points": OCTA_POINTS.tolist(), "faces": [[0, 1, 99]]}),
        "faces_big_int": dump({"points": OCTA_POINTS.tolist(), "faces": [[0, 1, 10**30]]}),
        "faces_negative": dump({"points": OCTA_POINTS.tolist(), "faces": [[0, -1, 2]]}),
        "faces_scalar": dump({"points": OCTA_POINTS.tolist(), "faces": 3}),
        "surface": dump({"points": OCTA_POINTS.tolist(), "faces": OCTA_FACES.tolist()}),
        "duplicates": dump(pts[:3] * 3),
        "collinear": dump([[float(i), 2.0 * i] for i in range(8)]),
        "tiny": dump((CONTOUR * 1e-310).tolist()),
        "huge_coords": dump((CONTOUR * 1e307).tolist()),
        "trailing_comma": b"[[1, 2], [3, 4], [5, 6],]",
        "latin1": b'{"points": [[1, 2], [3, 4], [5, 6]], "n\xe9": 1}',
    }


def _svg_cases() -> dict[str, bytes]:
    return {
        "no_shapes": _svg("<text>hello</text>"),
        "empty_path": _svg('<path d=""/>'),
        "bad_path": _svg('<path d="M 0 0 L x y"/>'),
        "move_only": _svg('<path d="M 10 10"/>'),
        "nan_path": _svg('<path d="M 0 0 L nan 10 L 10 10 Z"/>'),
        "huge_path": _svg('<path d="M 0 0 L 1e400 10 L 10 10 Z"/>'),
        "big_int_path": _svg(f'<path d="M 0 0 L {"9" * 400} 10 L 10 10 Z"/>'),
        "zero_circle": _svg('<circle cx="5" cy="5" r="0"/>'),
        "negative_rect": _svg('<rect x="0" y="0" width="-5" height="3"/>'),
        "point_polygon": _svg('<polygon points="1,1 1,1 1,1"/>'),
        "line_polygon": _svg('<polygon points="0,0 1,1 2,2"/>'),
        "odd_points": _svg('<polygon points="0,0 1"/>'),
        "bad_transform": _svg('<path transform="rotate(x)" d="M0 0 L 5 0 L 5 5 Z"/>'),
        "singular_transform": _svg('<path transform="scale(0)" d="M0 0 L 5 0 L 5 5 Z"/>'),
        "huge_transform": _svg('<path transform="scale(1e308)" d="M0 0 L 5 0 L 5 5 Z"/>'),
        "only_defs": _svg('<defs><circle r="3"/></defs>'),
        "entities": (b'<?xml version="1.0"?><!DOCTYPE svg [<!ENTITY a "aaaaaaaaaa">'
                     b'<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
                     b'<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">'
                     b'<!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;">]>'
                     b'<svg xmlns="http://www.w3.org/2000/svg"><text>&d;&d;&d;</text>'
                     b'<rect width="5" height="5"/></svg>'),
        "external_entity": (b'<?xml version="1.0"?><!DOCTYPE svg [<!ENTITY x SYSTEM '
                            b'"file:///etc/passwd">]><svg xmlns="http://www.w3.org/2000/svg">'
                            b'<text>&x;</text></svg>'),
        "not_svg_xml": b"<root><a/></root>",
        "many_arcs": _svg('<path d="M0 0 ' + "A 5 5 0 1 1 10 0 " * 2000 + 'Z"/>'),
        "huge_viewbox": _svg('<rect width="5" height="5"/>').replace(
            b'height="100"', b'height="100" viewBox="0 0 0 0"'),
        "use_element": _svg('<defs><path id="p" d="M0 0 L5 0 L5 5Z"/></defs><use href="#p"/>'),
    }


def _image_cases(ext: str, rng) -> dict[str, bytes]:
    from PIL import Image

    cases = {
        "blank": _image(ext, np.zeros((20, 20), np.uint8)),
        "one_pixel": _image(ext, np.full((1, 1), 255, np.uint8)),
        "one_row": _image(ext, (np.arange(30) % 2 * 255).astype(np.uint8)[None]),
        "grey_noise": _image(ext, rng.integers(0, 256, (30, 30)).astype(np.uint8)),
        "speckle": _image(ext, (rng.random((30, 30)) < 0.5).astype(np.uint8) * 255),
        "full": _image(ext, np.full((20, 20), 255, np.uint8)),
        "rgb": _image(ext, np.dstack([_mask()] * 3)),
        "tiny_object": _image(ext, np.pad(np.full((1, 1), 255, np.uint8), 10)),
    }
    if ext in (".png", ".tif"):
        rgba = np.dstack([_mask()] * 3 + [_mask()])
        cases["rgba"] = _image(ext, rgba)
        cases["uint16"] = _image(ext, _mask().astype(np.uint16) * 200)
    if ext == ".tif":
        for label, fill in (("nan", np.nan), ("inf", np.inf)):
            arr = _mask().astype(np.float32)
            arr[3:6, 3:6] = fill
            cases[f"float_{label}"] = _image(ext, arr)
        cases["float_all_nan"] = _image(ext, np.full((10, 10), np.nan, np.float32))
        cases["float_constant"] = _image(ext, np.full((10, 10), 2.5, np.float32))
        buf = io.BytesIO()
        frames = [Image.fromarray(_mask()), Image.fromarray(np.zeros((5, 5), np.uint8))]
        frames[0].save(buf, format="TIFF", save_all=True, append_images=frames[1:])
        cases["multipage"] = buf.getvalue()
    if ext == ".png":
        good = _image(ext, _mask())
        # an IHDR claiming 100000 x 100000 pixels (a decompression bomb)
        cases["bomb_header"] = good[:16] + struct.pack(">II", 100000, 100000) + good[24:]
        cases["zero_size_header"] = good[:16] + struct.pack(">II", 0, 0) + good[24:]
    return cases


def _mesh_cases(ext: str) -> dict[str, bytes]:
    cases = {"points_only": _mesh(ext, faces=None, fmt="gmsh" if ext == ".msh" else None)
             if ext not in (".stl", ".obj", ".off", ".mesh") else b""}
    if ext == ".off":
        cases.update({
            "off_only": b"OFF\n",
            "no_faces": b"OFF\n6 0 0\n" + b"".join(
                f"{x} {y} {z}\n".encode() for x, y, z in OCTA_POINTS),
            "absurd_counts": b"OFF\n999999999999 999999999999 0\n0 0 0\n",
            "negative_counts": b"OFF\n-5 -1 0\n",
            "counts_only": b"OFF\n6 8 0\n",
            "bad_face_index": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
            "letters": b"OFF\n3 1 0\na b c\n1 0 0\n0 1 0\n3 0 1 2\n",
        })
    elif ext == ".ply":
        cases.update({
            "ply_only": b"ply\n",
            "header_only": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                           b"property float y\nproperty float z\nend_header\n",
            "absurd_count": b"ply\nformat binary_little_endian 1.0\nelement vertex "
                            b"999999999999\nproperty float x\nproperty float y\n"
                            b"property float z\nend_header\n" + bytes(24),
            "no_end_header": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n",
            "bad_format": b"ply\nformat weird 9.0\nend_header\n",
            "no_faces": b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n"
                        b"property float y\nproperty float z\nend_header\n"
                        b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n",
        })
    elif ext == ".obj":
        cases.update({
            "vertices_only": b"".join(f"v {x} {y} {z}\n".encode() for x, y, z in OCTA_POINTS),
            "bad_face": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
            "zero_face": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            "letters": b"v a b c\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "nan": b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        })
    elif ext == ".stl":
        cases.update({
            "binary_absurd_count": bytes(80) + struct.pack("<I", 2**32 - 1) + bytes(50),
            "binary_zero": bytes(80) + struct.pack("<I", 0),
            "solid_only": b"solid x\n",
            "ascii_truncated": b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n",
        })
    elif ext == ".msh":
        ansys = (b"(0 \"ansys\")\n(10 (0 1 3 0))\n(10 (1 1 3 1 3)(\n0 0 0\n1 0 0\n0 1 0\n))\n"
                 b"(13 (0 1 1 0))\n(13 (3 1 1 3 3)(\n3 1 2 3 1 0\n))\n")
        cases.update({
            "ansys": ansys,
            "ansys_truncated": ansys[: len(ansys) // 2],
            "ansys_header": b"(0 \"ansys\")\n",
            "ansys_unknown_index": b"(3 (1 2 3))\n",
            "gmsh_header_only": b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n",
            "gmsh_old": _mesh(ext, fmt="gmsh22"),
        })
    elif ext == ".vtk":
        cases["absurd_points"] = (b"# vtk DataFile Version 4.2\nx\nASCII\nDATASET "
                                  b"UNSTRUCTURED_GRID\nPOINTS 999999999999 double\n0 0 0\n")
        cases["header_only"] = b"# vtk DataFile Version 4.2\n"
    elif ext == ".vtu":
        cases["not_vtk_xml"] = b"<?xml version='1.0'?><VTKFile type='Other'></VTKFile>"
    elif ext == ".mesh":
        cases["header_only"] = b"MeshVersionFormatted 2\nDimension 3\n"
        cases["absurd_vertices"] = b"MeshVersionFormatted 2\nDimension 3\nVertices\n99999999999\n"
    return {k: v for k, v in cases.items() if v}


def corpus(seed: int = 20050328) -> dict[str, bytes]:
    """File name -> content of every file in the corpus (deterministic for a seed)."""
    rng = np.random.default_rng(seed)
    files: dict[str, bytes] = {}

    def add(ext, base, extra):
        files[f"base{ext}"] = base
        for label, data in {**_mutations(base, rng), **extra}.items():
            files[f"{label}{ext}"] = data

    text_cases = _text_cases(CONTOUR, OCTA_POINTS)
    add(".csv", _text(CONTOUR), text_cases)
    add(".tsv", _text(CONTOUR, "\t"),
        {k: v.replace(b",", b"\t") for k, v in text_cases.items()})
    add(".txt", _text(CONTOUR, " ", header=False),
        {k: v.replace(b",", b" ") for k, v in text_cases.items()})
    add(".xyz", _text(OCTA_POINTS, " ", header=False),
        {k: v.replace(b",", b" ") for k, v in text_cases.items()})
    add(".npy", _npy(CONTOUR), _npy_cases(rng))
    add(".npz", _npz(points=OCTA_POINTS, faces=OCTA_FACES), _npz_cases())
    add(".json", json.dumps({"points": CONTOUR.tolist(), "closed": True}).encode(),
        _json_cases())
    add(".svg", _svg('<path d="M 10 10 C 20 0 40 0 50 10 L 50 50 L 10 50 Z"/>'),
        _svg_cases())
    for ext in _IMAGE_EXTS:
        add(ext, _image(ext, _mask()), _image_cases(ext, rng))
    for ext in _MESH_EXTS:
        add(ext, _mesh(ext), _mesh_cases(ext))
    for ext in (".nii", ".nii.gz"):
        add(ext, _nifti(ext, _mask()), _nifti_cases(ext))
    return files


def write_corpus(folder, seed: int = 20050328) -> list[Path]:
    """Write the corpus into ``folder`` (created); returns the paths, sorted."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, data in corpus(seed).items():
        path = folder / name
        path.write_bytes(data)
        paths.append(path)
    return sorted(paths)


def write_good_csv(path) -> Path:
    """A valid 2D target contour (16 nodes) for morphing the corpus's files into."""
    t = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    Path(path).write_bytes(_text(np.c_[12 * np.cos(t), 5 * np.sin(t) + np.cos(2 * t)]))
    return Path(path)


def _run_cli(path: Path, good: Path, work: Path, timeout: float, env: dict):
    """Morph ``path`` into ``good`` in its own process: (exit code or "timeout", the
    problem or None)."""
    import shutil
    import subprocess

    folder = work / path.name
    folder.mkdir()
    src = folder / path.name
    shutil.copy(path, src)
    shutil.copy(good, folder / "good.csv")
    try:
        proc = subprocess.run([sys.executable, "-m", "modalmorph.apps.cli", "morph", src.name,
                               "good.csv", "--out", "X"], cwd=folder, env=env,
                              capture_output=True, text=True, timeout=timeout)
        err = proc.stderr.strip().splitlines()
        left = sorted(p.name for p in folder.iterdir())
    except subprocess.TimeoutExpired:
        return "timeout", f"still running after {timeout:.0f} s"
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    expected = sorted([src.name, "good.csv"] + (["X"] if proc.returncode in (0, 3) else []))
    if proc.returncode not in (0, 2, 3):  # 3: written, tolerance not reached
        return proc.returncode, f"exit {proc.returncode}: {err[-1] if err else ''}"
    if any("Traceback" in line for line in err):
        return proc.returncode, f"traceback: {err[-1]}"
    if proc.returncode == 2 and len(err) != 1:
        return 2, f"{len(err)} lines on stderr: {' | '.join(err)[:300]}"
    if left != expected:
        return proc.returncode, f"left behind: {left}"
    return proc.returncode, None


def _read_all(paths) -> str:
    """read_shape on every file: counts of shapes, named ValueErrors and anything else."""
    import collections
    import time
    import warnings

    from modalmorph.io import read_shape

    counts, slowest = collections.Counter(), (0.0, "")
    for path in paths:
        start = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                read_shape(path)
            counts["shape"] += 1
        except ValueError as exc:
            counts["named ValueError" if str(exc).startswith(f"{path}: ") else
                   "unnamed ValueError"] += 1
        except Exception as exc:  # noqa: BLE001 - counted, that is the point
            counts[type(exc).__name__] += 1
        slowest = max(slowest, (time.perf_counter() - start, path.name))
    return (f"read_shape: {dict(counts)}; slowest {slowest[1]} {slowest[0]:.2f} s")


def main(argv=None) -> int:
    import argparse
    import collections
    import os
    import tempfile
    from concurrent.futures import ThreadPoolExecutor

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, help="where the corpus is written")
    parser.add_argument("--only", nargs="*", default=None, help="file names to run")
    parser.add_argument("--read-only", action="store_true",
                        help="only read every file with read_shape, in this process")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=30.0)
    args = parser.parse_args(argv)
    paths = write_corpus(args.folder)
    if args.only is not None:
        paths = [p for p in paths if p.name in args.only]
    print(_read_all(paths))
    if args.read_only:
        return 0
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg",
               PYTHONPATH=os.pathsep.join([str(Path(__file__).parents[1] / "src"),
                                           os.environ.get("PYTHONPATH", "")]))
    with tempfile.TemporaryDirectory() as tmp:
        good = write_good_csv(Path(tmp) / "good.csv")
        work = Path(tmp) / "runs"
        work.mkdir()
        with ThreadPoolExecutor(args.jobs) as pool:
            problems = list(pool.map(
                lambda p: _run_cli(p, good, work, args.timeout, env), paths))
    by_ext = collections.Counter(p.suffix for p in paths)
    codes = collections.Counter(str(code) for code, _ in problems)
    bad = [(p.name, why) for p, (_, why) in zip(paths, problems, strict=True) if why]
    for name, why in bad:
        print(f"FAIL {name}: {why}")
    print(f"{len(paths)} files ({', '.join(f'{e} {n}' for e, n in sorted(by_ext.items()))})")
    print(f"outcomes: {dict(sorted(codes.items()))}; {len(bad)} failures")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
