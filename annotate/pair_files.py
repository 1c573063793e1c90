"""What a saved pair's files hold, the same for a create and an update.

The text of the files is :func:`scenes.talk2radar.writer.sample_text` (the one function that turns a sample
into its files, for the writer's creates and the store's edits); this module adds what only a
saved pair has: its sidecar (:func:`pair_meta`: the prompt's type tags, the draft boxes as actors
and the annotation facts), and the image size its 2D boxes are clipped to
(:func:`frame_image_size`). A test saves one pair both ways and compares the bytes.
"""

from __future__ import annotations

from annotate.draft import Draft
from annotate.errors import StoreError
from annotate.manifest import ManifestRecord
from annotate.suggest import SuggestConfig, scene_actors
from scenes.frame import Sample
from scenes.frame.image import ImageError
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.classes import VOD, ClassSet
from scenes.language.prompts import infer_tags


def frame_image_size(sample: Sample) -> tuple[int, int]:
    """The image size the pair's 2D boxes are clipped to: the frame's camera image's, VoD's
    without one (:attr:`scenes.frame.Sample.image_size`); an unreadable image is a
    :class:`~annotate.errors.StoreError` naming the file."""
    try:
        return sample.image_size
    except ImageError as exc:
        raise StoreError(str(exc)) from exc


def pair_meta(
    draft: Draft, sample: Sample, record: ManifestRecord, classes: ClassSet = VOD
) -> SampleMeta:
    """The sidecar of a saved pair: keyword type tags of the prompt, the draft boxes as actors
    (ids ``0..K-1``, velocities from the frame's known actors or its radar) plus the frame's other
    known actors of the store's class set ``classes``, and the annotation facts in ``extra``."""
    base = sample.meta
    actors = scene_actors(
        draft.box_array,
        draft.classes,
        base.actors if base is not None else (),
        sample.radar,
        SuggestConfig(classes=classes),
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


__all__ = ["frame_image_size", "pair_meta"]
