"""What a saved pair's text files hold, the same for a create and an update.

The prompt file is the stripped prompt and a line break; ``label_2`` lines have
:data:`LABEL_DECIMALS` decimals (as :class:`scenes.root.Talk2RadarWriter` writes them); the sidecar
(:func:`pair_meta`) holds the prompt's type tags, the draft boxes as actors and the annotation
facts. A test saves one pair both ways and compares the bytes.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

from annotate.draft import Draft
from annotate.manifest import ManifestRecord
from annotate.suggest import SuggestConfig, scene_actors
from scenes.kitti import ObjectLabel, format_label_line
from scenes.prompts import infer_tags
from scenes.root import Sample, SampleMeta

LABEL_DECIMALS = 6
"""Decimals of the numbers in written ``label_2`` lines (as :class:`Talk2RadarWriter`)."""


def label_text(labels: Sequence[ObjectLabel]) -> str:
    """The ``label_2`` file of ``labels``."""
    return "".join(format_label_line(lab, LABEL_DECIMALS) + "\n" for lab in labels)


def meta_text(meta: SampleMeta) -> str:
    """The sidecar file of ``meta``."""
    return json.dumps(meta.to_json(), indent=1)


def pair_meta(draft: Draft, sample: Sample, record: ManifestRecord) -> SampleMeta:
    """The sidecar of a saved pair: keyword type tags of the prompt, the draft boxes as actors
    (ids ``0..K-1``, velocities from the frame's known actors or its radar) plus the frame's other
    known actors, and the annotation facts in ``extra``."""
    base = sample.meta
    actors = scene_actors(
        draft.box_array,
        draft.classes,
        base.actors if base is not None else (),
        sample.radar,
        SuggestConfig(),
    )
    extra = dict(base.extra) if base is not None else {}
    extra.update(
        {
            "annotator": record.annotator,
            "annotated_at": record.time,
            "version": record.version,
            "source": dict(record.source),
            "refers_to_nothing": record.refers_to_nothing,
        }
    )
    return SampleMeta(
        tags=infer_tags(draft.prompt.strip()),
        actors=actors.all,
        referent_ids=tuple(a.actor_id for a in actors.referents),
        weather=base.weather if base is not None else "clear",
        ego_velocity=base.ego_velocity if base is not None else 0.0,
        world_id=base.world_id if base is not None else -1,
        radar_scans=base.radar_scans if base is not None else 5,
        extra=extra,
    )


__all__ = ["LABEL_DECIMALS", "label_text", "meta_text", "pair_meta"]
