"""The figures of a stance phase, checked on the drawn pixels: the pressure image lies
under its contours, in mm with a sensor pitch, with its unit on the colour bar."""

import numpy as np
import pytest

from modalmorph import stance
from modalmorph.figures.stance import plot_part_energy, plot_stance_frames

PITCH = 5.0  # mm per sensor
BLOCK = (slice(6, 8), slice(2, 4))  # a 2 x 2 contact: rows 6-7, columns 2-3
CENTRE = np.array([2.5, 6.5]) * PITCH  # its centre (x, y) in mm
# A sensor is 5 mm; the figure draws it ~20 display pixels tall: the image and the
# contour agree within a tenth of a sensor.
TOL_SENSORS = 0.1


def block_stance(**options):
    frames = np.zeros((3, 12, 8))
    frames[:, BLOCK[0], BLOCK[1]] = [[[100.0]], [[120.0]], [[90.0]]]
    return stance(frames, threshold=5.0, pixel_size=PITCH, min_sensors=1, **options)


def drawn_centre(fig, ax) -> np.ndarray:
    """Display coordinates of the loaded sensors' pixels in ``ax`` (lines hidden)."""
    for line in ax.lines:
        line.set_visible(False)
    fig.canvas.draw()
    rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(float)
    x0, y0, x1, y1 = ax.get_window_extent().extents.astype(int)
    height = rgb.shape[0]
    box = rgb[height - y1:height - y0, x0:x1]  # rows of the buffer run down
    rows, cols = np.nonzero(box.sum(axis=2) > 150)  # brighter than magma's dark end
    return np.array([x0 + cols.mean() + 0.5, y1 - rows.mean() - 0.5])


def test_pressure_under_its_contour_in_mm():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    result = block_stance(pressure_unit="kPa")
    fig = Figure(figsize=(3, 4), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    plot_stance_frames(result, frames=[1], fig=fig)
    ax = fig.axes[0]
    contour = result.observed[1].contours[0]
    assert contour.mean(axis=0) == pytest.approx(CENTRE, abs=0.05 * PITCH)
    drawn = drawn_centre(fig, ax)  # drawn first: the layout places the axes then
    expected = ax.transData.transform(contour.mean(axis=0))
    sensor = abs(ax.transData.transform([0, PITCH])[1] - ax.transData.transform([0, 0])[1])
    assert sensor > 10  # display pixels: the test can see a tenth of a sensor
    assert np.abs(drawn - expected).max() < TOL_SENSORS * sensor
    assert ax.get_xlabel() == "x (mm)" and ax.get_ylabel().startswith("y (mm)")
    assert fig.axes[-1].get_ylabel() == "pressure (kPa)"  # the colour bar


def test_units_said_without_a_pitch_or_unit():
    result = stance(np.pad(np.full((2, 3, 3), 50.0), ((0, 0), (2, 2), (2, 2))),
                    threshold=5.0)
    fig = plot_stance_frames(result)
    assert fig.axes[0].get_xlabel() == "x (sensors)"
    assert fig.axes[-1].get_ylabel() == "pressure (the input's units)"


def test_energy_legend_beside_the_curves():
    """The legend sits right of the axes: it hides no curve."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.4, 3.6), layout="constrained")
    FigureCanvasAgg(fig)  # a canvas that draws (and lays out)
    ax = fig.add_subplot()
    plot_part_energy(block_stance(), ax=ax)
    fig.canvas.draw()
    legend = fig.legends[0].get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1
    assert legend.x1 <= fig.bbox.x1  # not clipped
