"""The annotation domain, with no GUI in it: drafts of prompt-to-box pairs with undo / redo,
validation, box fitting, per-box sensor evidence, prompt suggestion, and the store that saves pairs
atomically into a Talk2Radar root (see ``docs/ANNOTATION.md``).

Dependency direction: ``app -> annotate -> scenes``; nothing here imports ``app`` or ``model``.
"""

from annotate.draft import (
    DEFAULT_SIZES,
    Draft,
    DraftBox,
    DraftEditor,
    DraftError,
    History,
    default_box,
)
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
from annotate.store import (
    Action,
    AnnotationStore,
    ConflictError,
    DiskFullError,
    ManifestRecord,
    PairInfo,
    SaveError,
    SaveResult,
    SourceFrame,
    StoreError,
    read_manifest,
)
from annotate.suggest import SceneObject, SuggestConfig, Suggestion, scene_actors, suggest_prompt
from annotate.validation import (
    Issue,
    Severity,
    ValidationConfig,
    ValidationError,
    ValidationReport,
    validate,
)

__all__ = [
    "DEFAULT_SIZES",
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
    "StoreError",
    "SuggestConfig",
    "Suggestion",
    "ValidationConfig",
    "ValidationError",
    "ValidationReport",
    "box_evidence",
    "classify_motion",
    "convex_hull",
    "default_box",
    "estimate_velocity",
    "fit_box",
    "min_area_rectangle",
    "read_manifest",
    "scene_actors",
    "suggest_prompt",
    "validate",
]
