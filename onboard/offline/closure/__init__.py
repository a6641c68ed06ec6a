"""Model closure on measured data (``onboard diagnose``).

Run the vehicle model on a log, find where its residuals are not white noise, trace that to
the physical effect the model lacks, add the effect and report the error before and after
on data the fit did not see (architecture.md §4.3).

Modules: :mod:`.dataset` (a log -> aligned measured channels), :mod:`.channels` (the base
model and its residual channels), :mod:`.effects` (one module per effect in the vocabulary),
:mod:`.stats` (whiteness, spectra), :mod:`.select` (three-way split, selection,
unexplained structure), :mod:`.drift` (parameters per time window), :mod:`.report`
(diagnosis.json and report.html).
"""
