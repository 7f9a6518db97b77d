"""The pictures' shared helpers."""

from __future__ import annotations

import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from bagtools.figures import tidy_layout  # noqa: E402


def test_a_layout_that_cannot_fit_is_left_as_it_is_without_a_warning() -> None:
    """Labels too large for the figure: matplotlib's tight_layout warns ('Tight layout not applied'), which landed
    on the user's terminal from tf point; the picture is still written."""
    fig, axes = plt.subplots(2, 1, figsize=(2, 2))
    axes[0].set_ylabel("y\n" * 40)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tidy_layout(fig)
    plt.close(fig)
