"""The annotation domain, with no GUI in it: drafts of prompt-to-box pairs with undo / redo,
validation, box fitting, per-box sensor evidence, prompt suggestion, and the store that saves pairs
atomically into a Talk2Radar root (see ``docs/ANNOTATION.md``; the store is :mod:`annotate.store`
over :mod:`annotate.manifest`, :mod:`annotate.journal`, :mod:`annotate.transaction` and
:mod:`annotate.tree`).

Dependency direction: ``app -> annotate -> scenes``; nothing here imports ``app`` or ``model``.
"""

from annotate.draft import (
    Draft,
    DraftBox,
    DraftError,
    changed_box,
    default_box,
    is_pristine,
)
from annotate.editor import DraftEditor, History
from annotate.errors import ConflictError, DiskFullError, SaveError, SplitError, StoreError
from annotate.evidence import (
    BoxEvidence,
    EvidenceConfig,
    Motion,
    box_evidence,
    classify_motion,
    estimate_velocity,
)
from annotate.fitting import (
    BoxRegion,
    DiskRegion,
    FitConfig,
    FitError,
    FitResult,
    convex_hull,
    fit_box,
    min_area_rectangle,
)
from annotate.manifest import Action, ManifestRecord, PairInfo, read_manifest
from annotate.proposals import DUPLICATE_IOU, MAX_PROPOSALS, proposals
from annotate.source import SourceFrame
from annotate.store import DEFAULT_SPLITS, AnnotationStore, SaveResult
from annotate.suggest import (
    SceneObject,
    SuggestConfig,
    Suggestion,
    scene_actors,
    scene_objects,
    suggest_prompt,
)
from annotate.validation import (
    Issue,
    Severity,
    ValidationConfig,
    ValidationError,
    ValidationReport,
    validate,
)

__all__ = [
    "DEFAULT_SPLITS",
    "DUPLICATE_IOU",
    "MAX_PROPOSALS",
    "Action",
    "AnnotationStore",
    "BoxEvidence",
    "BoxRegion",
    "ConflictError",
    "DiskFullError",
    "DiskRegion",
    "Draft",
    "DraftBox",
    "DraftEditor",
    "DraftError",
    "EvidenceConfig",
    "FitConfig",
    "FitError",
    "FitResult",
    "History",
    "Issue",
    "ManifestRecord",
    "Motion",
    "PairInfo",
    "SaveError",
    "SaveResult",
    "SceneObject",
    "Severity",
    "SourceFrame",
    "SplitError",
    "StoreError",
    "SuggestConfig",
    "Suggestion",
    "ValidationConfig",
    "ValidationError",
    "ValidationReport",
    "box_evidence",
    "changed_box",
    "classify_motion",
    "convex_hull",
    "default_box",
    "estimate_velocity",
    "fit_box",
    "is_pristine",
    "min_area_rectangle",
    "proposals",
    "read_manifest",
    "scene_actors",
    "scene_objects",
    "suggest_prompt",
    "validate",
]
