"""Talk2Car on nuScenes: the commands' predictions (:mod:`.predict`), the metrics of the paper's
table II and Talk2Car's own (:mod:`.metrics`) and the report ``model.evaluate --talk2car`` prints
(:mod:`.report`)."""
