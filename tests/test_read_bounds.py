"""What a small file may make a reader spend is bounded before it is spent, on any thread
(review17 #1): an SVG whose <use>s multiply, an image declaring more pixels than Pillow's
bound while another thread's warning filters change. Bounded by counts, never by time."""

import struct
import threading
import warnings
import zlib

import pytest

from modalmorph.errors import InputFileError
from modalmorph.io import read_shape
from modalmorph.io.limits import MAX_SVG_ELEMENTS, LimitError, Limits, check_svg, svg_elements

se = pytest.importorskip("svgelements")

_HEAD = ('<svg xmlns="http://www.w3.org/2000/svg" '
         'xmlns:xlink="http://www.w3.org/1999/xlink">')


def fanout(depth: int, copies: int = 10) -> str:
    """Groups that each <use> the group below ``copies`` times, ``depth`` deep (review17's
    file: 1.6 kB at depth 6, a million triangles drawn)."""
    groups = "".join(f'<g id="p{i + 1}">' + f'<use xlink:href="#p{i}"/>' * copies + "</g>"
                     for i in range(depth))
    return (f'{_HEAD}<defs><path id="p0" d="M0 0 L10 0 L10 10 Z"/>{groups}</defs>'
            f'<use xlink:href="#p{depth}"/></svg>')


def _write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


def _reading(path, errors: list):
    """A call reading ``path`` that keeps the message of an InputFileError in ``errors``
    (run on a thread, where an exception would be lost)."""
    def read():
        try:
            read_shape(path)
        except InputFileError as exc:
            errors.append(str(exc))
    return read


def _expanded_by_svgelements(path) -> int:
    """The elements svgelements' structure pass yields (its own expansion of <use>)."""
    return sum(event == "start" for _, event, _ in se.SVG._use_structure_parse(str(path)))


@pytest.mark.parametrize("text", [
    fanout(2), fanout(3, copies=3),
    _HEAD + '<defs><g id="a"><use href="#b"/><use xlink:href="#b"/></g><g id="b">'
    '<path id="c" d="M0 0 H1 V1 Z"/><use xlink:href="#c"/></g></defs><use href="#a"/>'
    '<use xlink:href="#nowhere"/><use/></svg>',
    _HEAD + '<path id="x" d="M0 0 H1 V1 Z"/><use href="#x" xlink:href="#none"/></svg>'])
def test_svg_elements_counts_what_svgelements_expands(tmp_path, text):
    path = _write(tmp_path, "u.svg", text)
    assert svg_elements(path) == _expanded_by_svgelements(path)


@pytest.mark.parametrize("on_thread", [False, True])  # the CLI's main thread, dask's threads
def test_svg_use_fanout_is_refused_by_its_count_before_it_is_drawn(tmp_path, monkeypatch,
                                                                    on_thread):
    path = _write(tmp_path, "fanout6.svg", fanout(6))
    assert path.stat().st_size < 2000

    def drawn(*args, **kwargs):
        raise AssertionError("svgelements was asked to draw it")

    monkeypatch.setattr(se.SVG, "parse", drawn)
    errors = []
    read = _reading(path, errors)

    if on_thread:
        thread = threading.Thread(target=read)
        thread.start()
        thread.join()
    else:
        read()
    expected = svg_elements(path)
    assert expected == 4_691_351 > MAX_SVG_ELEMENTS
    assert errors == [f"{path}: {expected} elements once each <use> is expanded, the limit "
                      f"(max_svg_elements) is {MAX_SVG_ELEMENTS}"]


def test_svg_within_the_limit_reads_and_check_svg_names_the_limit(tmp_path):
    path = _write(tmp_path, "fanout2.svg", fanout(2))
    assert check_svg(path) == svg_elements(path) == 467
    assert read_shape(path, nodes=30).m == 30
    with pytest.raises(LimitError, match=r"^fanout2.svg: 467 elements .* is 100$") as info:
        check_svg(path, Limits(max_svg_elements=100))
    assert info.value.limit == "max_svg_elements"


def test_svg_use_of_its_own_container_is_refused_as_endless(tmp_path):
    path = _write(tmp_path, "selfuse.svg", _HEAD + '<g id="g"><path d="M0 0 H1 V1 Z"/>'
                  '<use xlink:href="#g"/></g></svg>')
    with pytest.raises(InputFileError, match=r"selfuse.svg: a <use> draws an element that "
                       r"contains it \(id 'g'\)"):
        read_shape(path)
    cycle = _write(tmp_path, "cycle.svg", _HEAD + '<defs><g id="a"><use href="#b"/></g>'
                   '<g id="b"><use href="#a"/></g></defs><use href="#a"/></svg>')
    with pytest.raises(InputFileError, match="endless drawing"):
        read_shape(cycle)


def _png_header(width: int, height: int) -> bytes:
    """A PNG that declares ``width`` x ``height`` grey pixels and holds none."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(
            ">I", zlib.crc32(kind + data))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(b"\0" * 100)) + chunk(b"IEND", b""))


def test_image_over_pillows_bound_is_refused_while_another_thread_resets_warnings(
        tmp_path, monkeypatch):
    """Pillow only warns between 1 and 2 times MAX_IMAGE_PIXELS; the reader made that
    warning an error in a ``catch_warnings`` block, whose filters another thread leaving
    its own block restores (they are global). Here that happens between the reader's
    block and its Image.open: the image must still be refused before it is decoded."""
    from PIL import Image, ImageFile

    width = height = 10_000  # 1e8 pixels, over 89.5 M and under twice it
    assert Image.MAX_IMAGE_PIXELS < width * height < 2 * Image.MAX_IMAGE_PIXELS
    path = tmp_path / "big.png"
    path.write_bytes(_png_header(width, height))
    entered, left = threading.Event(), threading.Event()
    real_open, decoded = Image.open, []

    def open_later(*args, **kwargs):  # the reader, inside its catch_warnings block
        entered.set()
        left.wait(30)
        return real_open(*args, **kwargs)

    def load(self, *args, **kwargs):
        decoded.append(self.size)
        raise OSError("decoded")

    monkeypatch.setattr(Image, "open", open_later)
    monkeypatch.setattr(ImageFile.ImageFile, "load", load)
    errors = []
    read = _reading(path, errors)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the process's filters: warnings not raised
        with warnings.catch_warnings():  # another thread's block, entered before the reader's
            reader = threading.Thread(target=read)
            reader.start()
            assert entered.wait(30)
        left.set()  # left while the reader is in its block: the reader's filter is gone
        reader.join(60)
    assert not decoded
    assert len(errors) == 1 and "10000 x 10000 pixels" in errors[0] \
        and "MAX_IMAGE_PIXELS" in errors[0], errors
