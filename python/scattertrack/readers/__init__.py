"""Live sources: real readers in, as the reads ``reads.csv`` holds.

* :mod:`~scattertrack.readers.impinj` — what an Impinj (Octane LLRP) tag
  report means: phase units, Doppler units, the hop table that maps a
  report's channel index to its carrier. Pure functions.
* :mod:`~scattertrack.readers.live` — :class:`LiveSession`: an LLRP reader
  (through llrpkit) in; a journal (``reads.csv``, every read as it
  arrives) and a causal track (``track.csv``) out; reconnects; a hard
  wall-clock stop.
* :mod:`~scattertrack.readers.emulator` — :class:`SimulatedReader`: an LLRP
  reader on loopback whose reports are a physical simulation, encoded as
  an Impinj reader encodes them (shuffled hop table, 0–4095 phase units).

The contract every live source keeps: a read is journaled before it is
tracked, exactly once, with the values the tracker uses, so that tracking
the journal offline gives the live track.
"""
