"""The one rendering layer: text, tables and figures of the result dicts it is handed.

``bsp-train``/``bsp-eval`` (:mod:`bsp_fast.training`) and ``bsp-reproduce``
(:mod:`bsp_fast.reproduction`) compute and collect; what they print, write as markdown or
draw is rendered here, from their dicts and the metric declarations
(:mod:`bsp_fast.metrics.spec`) they hand over. This package imports neither of them (it
stands below both), and its modules import matplotlib only when they draw.

* :mod:`.values`: the one value formatter of every table;
* :mod:`.run_tables`: ``bsp-eval --table`` and the table bsp-train prints;
* :mod:`.curves`: a run's ``curves.png``, and the helper every figure is saved with;
* :mod:`.breakdown`: ``bsp-eval --breakdown``'s text and a table's breakdown over seeds;
* :mod:`.findings`: a finding's cells, made when the finding is (one run, or with seeds);
* :mod:`.reproduced`: a reproduced table, its findings, marks and notes (``results.md``);
* :mod:`.figures`: a table file's declared figures and its learning curves;
* :mod:`.estimate`: ``bsp-reproduce --estimate``'s table and verdict;
* :mod:`.results_page`: the sections of docs/results.md from the published tables.
"""
