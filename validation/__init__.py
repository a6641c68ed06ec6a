"""The evidence behind every published number, kept outside the installed package: the
runs and reports that recompute the README's and the docs' figures (:mod:`.reports`), the
figure registry (:mod:`.figures`), the tuning protocol (:mod:`.tuning`) and the
diagnose campaign, and the tables they fill in: Markdown templates under ``templates/``
filled by one renderer (:mod:`.render`; docs/reproducing.md). Run from a checkout:
``python -m validation ...``."""
