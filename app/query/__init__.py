"""The Query tab: a typed prompt read once, run through the engine, its answer drawn.

- :mod:`~app.query.prompt`: the prompt policy, applied once where text enters
  (:func:`~app.query.prompt.read_prompt` -> :class:`~app.query.prompt.Prompt`, trusted after, or
  :class:`~app.query.prompt.Refused`);
- :mod:`~app.query.panel`: the tab's widgets, the prompt box that belongs to the person typing
  in it, the history;
- :mod:`~app.query.request`: one run (:class:`~app.query.request.QueryRequest`) and the model's
  answer to it in an engine worker;
- :mod:`~app.query.answer`: the answer on screen (boxes, heatmap, summary), with
  :mod:`~app.query.answer_words` (the answer said in words) and :mod:`~app.query.heatmap_view`.

:class:`app.session.ClientSession` coordinates them for one browser (the generation number, the
lock, the listeners).
"""
