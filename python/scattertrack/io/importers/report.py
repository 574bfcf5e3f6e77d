"""What an import did: the columns it used, the rows it kept, and every row it did not keep, by reason."""

from __future__ import annotations

from dataclasses import dataclass, field

from scattertrack.io.types import SkipReport

FREQUENCY_SOURCES = {
    "row": "given in the row",
    "hop table": "from the scene's hop table",
    "US channel plan": "from the US channel plan in index order",
}
"""Where a kept row's frequency came from, in order of preference, and how the report says it."""


@dataclass
class ImportReport:
    """The account of one import (``import_FORMAT(paths, scene) -> (Reads, ImportReport)``).

    Nothing is dropped silently: ``rows`` = ``kept`` + ``duplicates`` + declined
    rows (``declined``, per file, by reason, with up to five 1-based lines
    each) + ``ignored`` (events that are not tag reads, such as the status
    events of a JSON stream: counted, not declined).
    """

    format: str
    files: list[str]
    columns: list[str] = field(default_factory=list)
    """How each reads.csv column was filled: ``"time_s <- 'timestamp' (microseconds since the epoch)"``."""
    rows: int = 0
    """Data rows (CSV) or events (JSON lines) seen, blank lines excluded."""
    kept: int = 0
    duplicates: int = 0
    """Rows identical to an earlier one in time, EPC, antenna, frequency and phase (dropped, counted)."""
    reordered: int = 0
    """Kept rows that were out of time order (sorted, not dropped)."""
    declined: dict[str, SkipReport] = field(default_factory=dict)
    """Per file: malformed or unusable rows by reason, with their lines."""
    ignored: dict[str, int] = field(default_factory=dict)
    """Events that are not tag reads, by kind (counted, not declined)."""
    frequency_from: dict[str, int] = field(default_factory=dict)
    """Kept rows by where their frequency came from (:data:`FREQUENCY_SOURCES`)."""
    hop_table_disagreements: int = 0
    """Rows whose own frequency disagrees with the scene's hop table for their channel index (kept, warned)."""

    def decline(self, path, line: int | None, reason: str) -> None:
        """Count one row of ``path`` (at 1-based ``line``) as declined for ``reason``."""
        self.declined.setdefault(str(path), SkipReport()).add(reason, line)

    @property
    def declined_total(self) -> int:
        return sum(report.total for report in self.declined.values())

    def declined_by_reason(self) -> dict[str, int]:
        """Declined rows by reason, over all files."""
        totals: dict[str, int] = {}
        for report in self.declined.values():
            for reason, n in report.counts.items():
                totals[reason] = totals.get(reason, 0) + n
        return totals

    def summary(self) -> str:
        """One line: kept rows, duplicates, reordered, declined by reason (with file and lines)."""
        text = (f"imported {self.rows} {'row' if self.rows == 1 else 'rows'} from {len(self.files)} "
                f"{'file' if len(self.files) == 1 else 'files'} ({self.format}): kept {self.kept}, "
                f"{self.duplicates} duplicate{'' if self.duplicates == 1 else 's'} dropped, "
                f"{self.reordered} reordered, declined {self.declined_total}")
        parts = []
        for reason, n in sorted(self.declined_by_reason().items()):
            where = []
            for path, report in self.declined.items():
                lines = report.examples.get(reason)
                if lines:
                    more = ", ..." if report.counts.get(reason, 0) > len(lines) else ""
                    where.append(f"{path} line{'s' if len(lines) > 1 or more else ''} {', '.join(map(str, lines))}{more}")
            parts.append(f"{n} {reason}" + (f" ({'; '.join(where)})" if where else ""))
        if parts:
            text += ": " + "; ".join(parts)
        if self.ignored:
            text += "; ignored " + ", ".join(f"{n} {kind}" for kind, n in sorted(self.ignored.items()))
        return text

    def lines(self) -> list[str]:
        """The report as printed by ``scattertrack import``: columns used, frequency sources, summary."""
        out = ["columns: " + "; ".join(self.columns)] if self.columns else []
        if self.frequency_from:
            sources = ", ".join(f"{self.frequency_from[s]} {words}" for s, words in FREQUENCY_SOURCES.items()
                                if self.frequency_from.get(s))
            out.append(f"frequencies: {sources}")
        if self.hop_table_disagreements:
            out.append(f"hop table: {self.hop_table_disagreements} rows disagree with the scene's (kept, warned)")
        out.append(self.summary())
        return out
