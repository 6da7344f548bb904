from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class ObservationEncoding(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    OBSERVATION_ENCODING_UNSPECIFIED: _ClassVar[ObservationEncoding]
    OBSERVATION_ENCODING_DENSE_F32: _ClassVar[ObservationEncoding]
    OBSERVATION_ENCODING_SPARSE_F32: _ClassVar[ObservationEncoding]
OBSERVATION_ENCODING_UNSPECIFIED: ObservationEncoding
OBSERVATION_ENCODING_DENSE_F32: ObservationEncoding
OBSERVATION_ENCODING_SPARSE_F32: ObservationEncoding

class ObservationSpec(_message.Message):
    __slots__ = ("kind", "shape", "extra_features")
    KIND_FIELD_NUMBER: _ClassVar[int]
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    EXTRA_FEATURES_FIELD_NUMBER: _ClassVar[int]
    kind: str
    shape: _containers.RepeatedScalarFieldContainer[int]
    extra_features: int
    def __init__(self, kind: _Optional[str] = ..., shape: _Optional[_Iterable[int]] = ..., extra_features: _Optional[int] = ...) -> None: ...

class ObservationPool(_message.Message):
    __slots__ = ("encoding", "offsets", "data")
    ENCODING_FIELD_NUMBER: _ClassVar[int]
    OFFSETS_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    encoding: ObservationEncoding
    offsets: _containers.RepeatedScalarFieldContainer[int]
    data: bytes
    def __init__(self, encoding: _Optional[_Union[ObservationEncoding, str]] = ..., offsets: _Optional[_Iterable[int]] = ..., data: _Optional[bytes] = ...) -> None: ...

class TransitionBatch(_message.Message):
    __slots__ = ("spec", "num_actions", "actions", "rewards", "discounts", "priorities", "observations", "observation_index", "next_observation_index")
    SPEC_FIELD_NUMBER: _ClassVar[int]
    NUM_ACTIONS_FIELD_NUMBER: _ClassVar[int]
    ACTIONS_FIELD_NUMBER: _ClassVar[int]
    REWARDS_FIELD_NUMBER: _ClassVar[int]
    DISCOUNTS_FIELD_NUMBER: _ClassVar[int]
    PRIORITIES_FIELD_NUMBER: _ClassVar[int]
    OBSERVATIONS_FIELD_NUMBER: _ClassVar[int]
    OBSERVATION_INDEX_FIELD_NUMBER: _ClassVar[int]
    NEXT_OBSERVATION_INDEX_FIELD_NUMBER: _ClassVar[int]
    spec: ObservationSpec
    num_actions: int
    actions: _containers.RepeatedScalarFieldContainer[int]
    rewards: _containers.RepeatedScalarFieldContainer[float]
    discounts: _containers.RepeatedScalarFieldContainer[float]
    priorities: _containers.RepeatedScalarFieldContainer[float]
    observations: ObservationPool
    observation_index: _containers.RepeatedScalarFieldContainer[int]
    next_observation_index: _containers.RepeatedScalarFieldContainer[int]
    def __init__(self, spec: _Optional[_Union[ObservationSpec, _Mapping]] = ..., num_actions: _Optional[int] = ..., actions: _Optional[_Iterable[int]] = ..., rewards: _Optional[_Iterable[float]] = ..., discounts: _Optional[_Iterable[float]] = ..., priorities: _Optional[_Iterable[float]] = ..., observations: _Optional[_Union[ObservationPool, _Mapping]] = ..., observation_index: _Optional[_Iterable[int]] = ..., next_observation_index: _Optional[_Iterable[int]] = ...) -> None: ...

class NetworkSpec(_message.Message):
    __slots__ = ("observation", "action_set", "num_actions", "trunk", "hidden", "extra_features")
    OBSERVATION_FIELD_NUMBER: _ClassVar[int]
    ACTION_SET_FIELD_NUMBER: _ClassVar[int]
    NUM_ACTIONS_FIELD_NUMBER: _ClassVar[int]
    TRUNK_FIELD_NUMBER: _ClassVar[int]
    HIDDEN_FIELD_NUMBER: _ClassVar[int]
    EXTRA_FEATURES_FIELD_NUMBER: _ClassVar[int]
    observation: ObservationSpec
    action_set: str
    num_actions: int
    trunk: str
    hidden: _containers.RepeatedScalarFieldContainer[int]
    extra_features: int
    def __init__(self, observation: _Optional[_Union[ObservationSpec, _Mapping]] = ..., action_set: _Optional[str] = ..., num_actions: _Optional[int] = ..., trunk: _Optional[str] = ..., hidden: _Optional[_Iterable[int]] = ..., extra_features: _Optional[int] = ...) -> None: ...

class Weights(_message.Message):
    __slots__ = ("version", "update_step", "spec", "safetensors", "published_unix_ms")
    VERSION_FIELD_NUMBER: _ClassVar[int]
    UPDATE_STEP_FIELD_NUMBER: _ClassVar[int]
    SPEC_FIELD_NUMBER: _ClassVar[int]
    SAFETENSORS_FIELD_NUMBER: _ClassVar[int]
    PUBLISHED_UNIX_MS_FIELD_NUMBER: _ClassVar[int]
    version: int
    update_step: int
    spec: NetworkSpec
    safetensors: bytes
    published_unix_ms: int
    def __init__(self, version: _Optional[int] = ..., update_step: _Optional[int] = ..., spec: _Optional[_Union[NetworkSpec, _Mapping]] = ..., safetensors: _Optional[bytes] = ..., published_unix_ms: _Optional[int] = ...) -> None: ...

class CheckpointInfo(_message.Message):
    __slots__ = ("id", "update_step", "weights_version", "created_unix_ms", "size_bytes", "scenario", "eval_metrics", "best", "files")
    class EvalMetricsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    ID_FIELD_NUMBER: _ClassVar[int]
    UPDATE_STEP_FIELD_NUMBER: _ClassVar[int]
    WEIGHTS_VERSION_FIELD_NUMBER: _ClassVar[int]
    CREATED_UNIX_MS_FIELD_NUMBER: _ClassVar[int]
    SIZE_BYTES_FIELD_NUMBER: _ClassVar[int]
    SCENARIO_FIELD_NUMBER: _ClassVar[int]
    EVAL_METRICS_FIELD_NUMBER: _ClassVar[int]
    BEST_FIELD_NUMBER: _ClassVar[int]
    FILES_FIELD_NUMBER: _ClassVar[int]
    id: str
    update_step: int
    weights_version: int
    created_unix_ms: int
    size_bytes: int
    scenario: str
    eval_metrics: _containers.ScalarMap[str, float]
    best: bool
    files: _containers.RepeatedScalarFieldContainer[str]
    def __init__(self, id: _Optional[str] = ..., update_step: _Optional[int] = ..., weights_version: _Optional[int] = ..., created_unix_ms: _Optional[int] = ..., size_bytes: _Optional[int] = ..., scenario: _Optional[str] = ..., eval_metrics: _Optional[_Mapping[str, float]] = ..., best: _Optional[bool] = ..., files: _Optional[_Iterable[str]] = ...) -> None: ...
