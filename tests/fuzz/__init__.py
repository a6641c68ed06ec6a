"""Fuzzing every parser: bad bytes never raise, every rejection is counted.

The contract (architecture.md §5): input from a serial line, a socket or a log file that
somebody else wrote gives a counted, reported rejection and never an exception.
docs/fuzzing.md describes the targets, the properties and the campaign results.

* :mod:`.mutation`: byte- and field-level mutations, chunking of a stream;
* :mod:`.corpora`: valid inputs from the project's own encoders, then mutated (NMEA,
  MAVLink, DVL JSON, PD6, CSV, tlog, DataFlash, text captures);
* :mod:`.recording_corpora`: the service's own recordings, format versions 1 and 2
  (signed MAVLink with ``verdicts`` records);
* :mod:`.properties`: what every produced sample and every counter must satisfy;
* :mod:`.targets`: each parser fed an input with its properties checked, and the
  registry :data:`.targets.TARGETS` the campaign runs;
* :mod:`.known_bugs`: exceptions already reported and still open, counted, not failed;
* ``test_properties.py``: hypothesis property tests (default suite);
* ``test_regressions.py``: minimal reproducers of what fuzzing found, one behaviour each;
* ``test_campaign.py``: the long seeded campaign (``slow``).
"""
