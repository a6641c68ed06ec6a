"""The monitors: what the engine reports about its pipelines, never feeding back into them.
The innovation records summarized per channel (:mod:`.innovations`), each estimate held
against an independent measurement (:mod:`.integrity`: heading against course, position
against GNSS, NIS against its chi-square band), and the warnings a user reads first
(:mod:`.alerts`)."""
