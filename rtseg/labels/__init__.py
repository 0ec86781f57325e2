"""Human labels of behaviour transitions: the label types (``types``), one reader per label
format (``cmu86``, ``frames``, ``mocap6``, ``npz``) and the pairing of labelled takes with
their motion (``takes``).  Frame numbers are 0-based frames of the take.

May import ``rtseg.core`` and ``rtseg.drivers.readers``."""

from rtseg.labels.takes import (
    DEFAULT_TOLERANCE,
    MOCAP6_BLOCK,
    MOCAP6_NAMES,
    SLIP_POLICIES,
    LabelError,
    Transition,
    TransitionLabels,
    read_cmu86_transitions,
    load_cmu86_transitions,
    transitions_from_frame_labels,
    read_block_labels,
    read_frame_label_column,
    read_frame_labels,
    labels_from_take,
    read_take_transitions,
    GROUPS,
    LabelledTake,
    find_labelled_takes,
    read_labels_file,
    find_labels_for,
)

__all__ = [
    "DEFAULT_TOLERANCE",
    "MOCAP6_BLOCK",
    "MOCAP6_NAMES",
    "SLIP_POLICIES",
    "LabelError",
    "Transition",
    "TransitionLabels",
    "read_cmu86_transitions",
    "load_cmu86_transitions",
    "transitions_from_frame_labels",
    "read_block_labels",
    "read_frame_label_column",
    "read_frame_labels",
    "labels_from_take",
    "read_take_transitions",
    "GROUPS",
    "LabelledTake",
    "find_labelled_takes",
    "read_labels_file",
    "find_labels_for",
]
