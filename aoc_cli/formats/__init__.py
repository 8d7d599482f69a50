"""Readers that turn Minari, D4RL, d3rlpy, NPZ and CSV data into corpus rows, and
:func:`export`, which writes a corpus out again as Minari, D4RL HDF5 or CSV.

>>> from aoc_cli.formats import ingest, ReadOptions
>>> ingest("hopper-medium.hdf5", "hopper", options=ReadOptions(tags={"policy": "medium"}))
... # doctest: +SKIP

Every reader returns an :class:`aoc_cli.store.CorpusData` (rows (o_t, a_t, r_t), episodes
contiguous); :func:`detect_format` picks the reader, :func:`read_dataset` applies the options
shared by all formats, :func:`ingest` writes the result into the store.
"""

from aoc_cli.formats.common import ReadOptions
from aoc_cli.formats.detect import FORMATS, detect_format
from aoc_cli.formats.export import EXPORT_FORMATS, ExportResult, export
from aoc_cli.formats.ingest import IngestResult, ingest, read_dataset

__all__ = ["EXPORT_FORMATS", "FORMATS", "ExportResult", "IngestResult", "ReadOptions",
           "detect_format", "export", "ingest", "read_dataset"]
