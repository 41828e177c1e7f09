"""The floor every other part of primspace stands on: user errors, safe file and folder
output, the marks outputs carry, seeds, progress bars, worker processes and small statistics.

One module each: :mod:`~primspace.utils.errors` (``UserError`` and its one-line message),
:mod:`~primspace.utils.files` (atomic writes, locks, inputs never overwritten),
:mod:`~primspace.utils.outputs` (who wrote a file; the ``--overwrite`` rule),
:mod:`~primspace.utils.folders` (a command's output folder, published whole),
:mod:`~primspace.utils.seeds`, :mod:`~primspace.utils.progress`,
:mod:`~primspace.utils.parallel`, :mod:`~primspace.utils.stats`. Nothing here imports the
rest of primspace.
"""
