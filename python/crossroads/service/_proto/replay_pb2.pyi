from . import schema_pb2 as _schema_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class JoinActorRequest(_message.Message):
    __slots__ = ("name",)
    NAME_FIELD_NUMBER: _ClassVar[int]
    name: str
    def __init__(self, name: _Optional[str] = ...) -> None: ...

class JoinActorResponse(_message.Message):
    __slots__ = ("index", "joined")
    INDEX_FIELD_NUMBER: _ClassVar[int]
    JOINED_FIELD_NUMBER: _ClassVar[int]
    index: int
    joined: int
    def __init__(self, index: _Optional[int] = ..., joined: _Optional[int] = ...) -> None: ...

class InsertRequest(_message.Message):
    __slots__ = ("table", "batch_id", "batch")
    TABLE_FIELD_NUMBER: _ClassVar[int]
    BATCH_ID_FIELD_NUMBER: _ClassVar[int]
    BATCH_FIELD_NUMBER: _ClassVar[int]
    table: str
    batch_id: int
    batch: _schema_pb2.TransitionBatch
    def __init__(self, table: _Optional[str] = ..., batch_id: _Optional[int] = ..., batch: _Optional[_Union[_schema_pb2.TransitionBatch, _Mapping]] = ...) -> None: ...

class InsertAck(_message.Message):
    __slots__ = ("batch_id", "inserted", "table_size")
    BATCH_ID_FIELD_NUMBER: _ClassVar[int]
    INSERTED_FIELD_NUMBER: _ClassVar[int]
    TABLE_SIZE_FIELD_NUMBER: _ClassVar[int]
    batch_id: int
    inserted: int
    table_size: int
    def __init__(self, batch_id: _Optional[int] = ..., inserted: _Optional[int] = ..., table_size: _Optional[int] = ...) -> None: ...

class SampleRequest(_message.Message):
    __slots__ = ("table", "batch_size", "beta", "timeout_ms")
    TABLE_FIELD_NUMBER: _ClassVar[int]
    BATCH_SIZE_FIELD_NUMBER: _ClassVar[int]
    BETA_FIELD_NUMBER: _ClassVar[int]
    TIMEOUT_MS_FIELD_NUMBER: _ClassVar[int]
    table: str
    batch_size: int
    beta: float
    timeout_ms: int
    def __init__(self, table: _Optional[str] = ..., batch_size: _Optional[int] = ..., beta: _Optional[float] = ..., timeout_ms: _Optional[int] = ...) -> None: ...

class SampleResponse(_message.Message):
    __slots__ = ("keys", "weights", "priorities", "batch")
    KEYS_FIELD_NUMBER: _ClassVar[int]
    WEIGHTS_FIELD_NUMBER: _ClassVar[int]
    PRIORITIES_FIELD_NUMBER: _ClassVar[int]
    BATCH_FIELD_NUMBER: _ClassVar[int]
    keys: _containers.RepeatedScalarFieldContainer[int]
    weights: _containers.RepeatedScalarFieldContainer[float]
    priorities: _containers.RepeatedScalarFieldContainer[float]
    batch: _schema_pb2.TransitionBatch
    def __init__(self, keys: _Optional[_Iterable[int]] = ..., weights: _Optional[_Iterable[float]] = ..., priorities: _Optional[_Iterable[float]] = ..., batch: _Optional[_Union[_schema_pb2.TransitionBatch, _Mapping]] = ...) -> None: ...

class UpdatePrioritiesRequest(_message.Message):
    __slots__ = ("table", "keys", "priorities")
    TABLE_FIELD_NUMBER: _ClassVar[int]
    KEYS_FIELD_NUMBER: _ClassVar[int]
    PRIORITIES_FIELD_NUMBER: _ClassVar[int]
    table: str
    keys: _containers.RepeatedScalarFieldContainer[int]
    priorities: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, table: _Optional[str] = ..., keys: _Optional[_Iterable[int]] = ..., priorities: _Optional[_Iterable[float]] = ...) -> None: ...

class UpdatePrioritiesResponse(_message.Message):
    __slots__ = ("updated", "ignored")
    UPDATED_FIELD_NUMBER: _ClassVar[int]
    IGNORED_FIELD_NUMBER: _ClassVar[int]
    updated: int
    ignored: int
    def __init__(self, updated: _Optional[int] = ..., ignored: _Optional[int] = ...) -> None: ...

class InfoRequest(_message.Message):
    __slots__ = ("table",)
    TABLE_FIELD_NUMBER: _ClassVar[int]
    table: str
    def __init__(self, table: _Optional[str] = ...) -> None: ...

class RateLimiterInfo(_message.Message):
    __slots__ = ("min_size_to_sample", "samples_per_insert", "error_tolerance", "can_sample", "can_insert", "sample_waits_total", "insert_waits_total")
    MIN_SIZE_TO_SAMPLE_FIELD_NUMBER: _ClassVar[int]
    SAMPLES_PER_INSERT_FIELD_NUMBER: _ClassVar[int]
    ERROR_TOLERANCE_FIELD_NUMBER: _ClassVar[int]
    CAN_SAMPLE_FIELD_NUMBER: _ClassVar[int]
    CAN_INSERT_FIELD_NUMBER: _ClassVar[int]
    SAMPLE_WAITS_TOTAL_FIELD_NUMBER: _ClassVar[int]
    INSERT_WAITS_TOTAL_FIELD_NUMBER: _ClassVar[int]
    min_size_to_sample: int
    samples_per_insert: float
    error_tolerance: float
    can_sample: bool
    can_insert: bool
    sample_waits_total: int
    insert_waits_total: int
    def __init__(self, min_size_to_sample: _Optional[int] = ..., samples_per_insert: _Optional[float] = ..., error_tolerance: _Optional[float] = ..., can_sample: _Optional[bool] = ..., can_insert: _Optional[bool] = ..., sample_waits_total: _Optional[int] = ..., insert_waits_total: _Optional[int] = ...) -> None: ...

class TableInfo(_message.Message):
    __slots__ = ("name", "size", "capacity", "inserts_total", "samples_total", "priority_updates_total", "ignored_updates_total", "rejections_total", "rate_limiter", "bytes_stored", "last_snapshot_unix_ms")
    class RejectionsTotalEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    NAME_FIELD_NUMBER: _ClassVar[int]
    SIZE_FIELD_NUMBER: _ClassVar[int]
    CAPACITY_FIELD_NUMBER: _ClassVar[int]
    INSERTS_TOTAL_FIELD_NUMBER: _ClassVar[int]
    SAMPLES_TOTAL_FIELD_NUMBER: _ClassVar[int]
    PRIORITY_UPDATES_TOTAL_FIELD_NUMBER: _ClassVar[int]
    IGNORED_UPDATES_TOTAL_FIELD_NUMBER: _ClassVar[int]
    REJECTIONS_TOTAL_FIELD_NUMBER: _ClassVar[int]
    RATE_LIMITER_FIELD_NUMBER: _ClassVar[int]
    BYTES_STORED_FIELD_NUMBER: _ClassVar[int]
    LAST_SNAPSHOT_UNIX_MS_FIELD_NUMBER: _ClassVar[int]
    name: str
    size: int
    capacity: int
    inserts_total: int
    samples_total: int
    priority_updates_total: int
    ignored_updates_total: int
    rejections_total: _containers.ScalarMap[str, int]
    rate_limiter: RateLimiterInfo
    bytes_stored: int
    last_snapshot_unix_ms: int
    def __init__(self, name: _Optional[str] = ..., size: _Optional[int] = ..., capacity: _Optional[int] = ..., inserts_total: _Optional[int] = ..., samples_total: _Optional[int] = ..., priority_updates_total: _Optional[int] = ..., ignored_updates_total: _Optional[int] = ..., rejections_total: _Optional[_Mapping[str, int]] = ..., rate_limiter: _Optional[_Union[RateLimiterInfo, _Mapping]] = ..., bytes_stored: _Optional[int] = ..., last_snapshot_unix_ms: _Optional[int] = ...) -> None: ...

class SnapshotRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class SnapshotResponse(_message.Message):
    __slots__ = ("path", "items", "bytes", "duration_seconds")
    PATH_FIELD_NUMBER: _ClassVar[int]
    ITEMS_FIELD_NUMBER: _ClassVar[int]
    BYTES_FIELD_NUMBER: _ClassVar[int]
    DURATION_SECONDS_FIELD_NUMBER: _ClassVar[int]
    path: str
    items: int
    bytes: int
    duration_seconds: float
    def __init__(self, path: _Optional[str] = ..., items: _Optional[int] = ..., bytes: _Optional[int] = ..., duration_seconds: _Optional[float] = ...) -> None: ...
