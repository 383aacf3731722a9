"""A dataset version as a Hugging Face ``datasets.Dataset``, for analysis with ``map`` and ``filter``.

``datasets.Dataset.from_parquet`` would copy the frames into the Arrow cache;
here the version's Parquet data files are read memory-mapped into one Arrow
table and wrapped as is, so nothing is written.  The table's ``huggingface``
schema metadata (written with every data file) makes ``observation.image`` an
``Image`` feature.  Hugging Face's package is imported inside the function as
``hf_datasets``: this folder is ``nsl.datasets`` and must not shadow it.
"""

from __future__ import annotations

import pyarrow as pa
import pyarrow.parquet as pq

from .reader import DatasetView, open_view


def to_hf_dataset(ref: str | DatasetView):
    """The frames of ``NAME[@vN][:K]`` (a whole version or a tier) as an Arrow-backed ``datasets.Dataset``."""
    import datasets as hf_datasets

    view = open_view(ref)
    view.check(quick=True)
    v = view.version
    files = [v.root / v.data_file(n) for n in range(int(v.episodes.file_number.max()) + 1)]
    table = pa.concat_tables([pq.read_table(f, memory_map=True) for f in files])
    first, stop = view.frame_range
    return hf_datasets.Dataset(hf_datasets.table.InMemoryTable(table.slice(first, stop - first)))
