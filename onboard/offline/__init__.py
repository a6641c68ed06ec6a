"""The offline commands on recorded logs: ``onboard replay`` (:mod:`.replay`), the vehicle
class and input mapping detected from a log (:mod:`.autodetect`), the exports of a replay
(:mod:`.exports`: GeoJSON, GPX) and its track figure (:mod:`.plots`), and ``onboard
diagnose`` (:mod:`.diagnose`) with the model closure behind it (:mod:`.closure`)."""
