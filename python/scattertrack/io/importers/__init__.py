"""Importers of reader logs into :class:`~scattertrack.io.Reads` (``reads.csv``, docs/formats.md section 2).

Contract: every format has a function ``import_FORMAT(paths, scene) -> (Reads, report)``
(``report`` an :class:`ImportReport`), listed in :data:`IMPORTERS` by the name the
command line uses (``scattertrack import FORMAT FILES... --scene S --out reads.csv``):

- files are read in the order given, rows keep their file and 1-based line;
- units are converted to SI as each module's docstring says (docs/importers.md);
- a row's frequency is its own, else the scene's ``[[hop_table]]`` entry for
  its channel index, else the US channel plan in index order (902.75 +
  0.5*(index - 1) MHz) with one ``warning:`` saying so;
- malformed rows are declined and counted by reason with their file and line
  (``report.declined``); a file that cannot be read at all (not UTF-8, no
  header, a missing required column, a row with the wrong number of fields)
  raises :class:`~scattertrack.io.FormatError` naming file, line and column;
- rows naming an antenna the scene lacks are declined; exact duplicates are
  dropped and counted; rows are sorted by time, out-of-order rows counted;
- EPCs are written exactly as hex (``b'...'`` and ``0x`` unwrapped, base64 decoded);
- the reader's channel index is kept in ``Reads.channel_index``;
- a ValueError when no row is kept.

The result is what :func:`~scattertrack.io.write_reads` writes and
:func:`~scattertrack.io.read_reads` reads back unchanged.
"""

from scattertrack.io.importers.impinj_iot import import_impinj_iot
from scattertrack.io.importers.iq_phasors import import_iq_phasors
from scattertrack.io.importers.report import ImportReport
from scattertrack.io.importers.sllurp_csv import import_sllurp_csv

IMPORTERS = {
    "sllurp-csv": import_sllurp_csv,
    "impinj-iot": import_impinj_iot,
    "iq-phasors": import_iq_phasors,
}
"""Format name (as ``scattertrack import`` takes it) -> importer."""


def import_files(format: str, paths, scene):
    """Run the importer of ``format`` (a key of :data:`IMPORTERS`) on ``paths``: ``(Reads, ImportReport)``."""
    if format not in IMPORTERS:
        raise ValueError(f"unknown import format {format!r}: expected one of {', '.join(IMPORTERS)}")
    return IMPORTERS[format]([str(p) for p in paths], scene)


__all__ = ["IMPORTERS", "ImportReport", "import_files", "import_impinj_iot", "import_iq_phasors", "import_sllurp_csv"]
