"""Model criticism: where a joint model fails, which physics it lacks, and when the
catalogue does not explain it (:func:`~identification.criticism.criticism.criticize`).

One concept per module: :mod:`.config` (settings, the rules' constants and the verdicts),
:mod:`.decision` (the calibrated statistics, where the model fails), :mod:`.refits`
(candidate refits), :mod:`.candidates` (the candidates judged and ranked),
:mod:`.groups` (what the data cannot tell apart), :mod:`.moves` (add, swap, swap the
model's own term; the stepwise loop), :mod:`.records` (the result records),
:mod:`.words` and :mod:`.report` (words and JSON); :mod:`.criticism` holds the state of
one criticism and delegates.
"""
