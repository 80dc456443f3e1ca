"""The field's reader: ``mhkit.dolfyn`` (imported lazily; it is heavy and optional).

The standalone ``dolfyn`` 1.3.0 fails with numpy 2; the copy inside MHKiT (pinned in
the ``io`` extra) works, so that is the one used.
"""

from __future__ import annotations

import contextlib
import io
import warnings

# WinRiver II stores GGA latitude and longitude as float64; dolfyn keeps them as float32
# (about 1 m of resolution). These entries are read with float64 storage instead.
FLOAT64_FIELDS = ("latitude_gps", "longitude_gps")


class ImportFailure(ValueError):
    """A file cannot be imported; the message is one line naming what is missing."""


def reader_version() -> str:
    """``mhkit <version>`` (the dolfyn inside it), or raise ImportFailure when absent."""
    try:
        import mhkit
    except ImportError as exc:
        raise ImportFailure("reading instrument files needs mhkit (the dolfyn reader): "
                            "pip install 'adcpdyn[io]'") from exc
    return f"mhkit {mhkit.__version__} (mhkit.dolfyn)"


@contextlib.contextmanager
def _float64_gnss():
    from mhkit.dolfyn.io import rdi_defs

    saved = {k: rdi_defs.data_defs[k] for k in FLOAT64_FIELDS}
    try:
        for k, d in saved.items():
            rdi_defs.data_defs[k] = (d[0], d[1], "float64", *d[3:])
        yield
    finally:
        rdi_defs.data_defs.update(saved)


def read_dolfyn(path):
    """Read an instrument file with dolfyn; any failure becomes a one-line ImportFailure.

    Returns
    -------
    (xarray.Dataset, str)
        The dataset and the reader's version text.
    """
    version = reader_version()
    from mhkit import dolfyn

    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()), _float64_gnss():
            warnings.simplefilter("ignore")
            ds = dolfyn.read(str(path))
    except Exception as exc:  # the reader's own failure, reported in one line
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise ImportFailure(f"{path}: {version} could not read the file ({type(exc).__name__}: {text}); "
                            "adcpdyn has no reader of its own for it") from exc
    return ds, version
