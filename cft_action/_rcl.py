# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The ctypes binding to rcl: the only module that knows C signatures and struct layouts.

Jazzy's rclpy exposes no content-filter API, but ``librcl.so`` exports one; its action client
takes feedback and result responses without their sample info, which ``rcl_take`` and
``rcl_take_response_with_info`` return; and it converts every status sample whole to Python, where
``rcl_take_serialized_message`` gives the bytes for the status trim (``_status_trim.c``). Each C
symbol is declared once, in :data:`_SYMBOLS` below, with its argument and return types. Functions
that return ``rcl_ret_t`` get an ``errcheck`` that turns a non-OK code into
:class:`ContentFilterError` carrying rcl's own error string, and resets rcl's error state, so
nothing fails silently. A missing symbol is an error when this module loads, not a crash later.
"""

from __future__ import annotations

import ctypes
import os
from typing import Any, Callable, Optional, Sequence

# Importing rclpy's C extension loads librcl and friends from the installed wheels; we then bind
# to those very copies instead of guessing paths. A failed take raises its RCLError, as rclpy's.
from rclpy import get_rmw_implementation_identifier, ok
from rclpy.logging import get_logger

from cft_action._rclpy_compat import RCLError
from cft_action._native import extension_path, READER_FASTDDS3_LIBRARY, READER_LOCK_LIBRARY
from cft_action.errors import BindingUnavailable, ContentFilterError

RCL_RET_OK = 0
_RET_NAMES = {
    1: 'RCL_RET_ERROR',
    2: 'RCL_RET_TIMEOUT',
    3: 'RCL_RET_UNSUPPORTED',
    10: 'RCL_RET_BAD_ALLOC',
    11: 'RCL_RET_INVALID_ARGUMENT',
    200: 'RCL_RET_NODE_INVALID',
    400: 'RCL_RET_SUBSCRIPTION_INVALID',
}
RCL_RET_UNSUPPORTED = 3
RCL_RET_SUBSCRIPTION_TAKE_FAILED = 401
RCL_RET_CLIENT_TAKE_FAILED = 501


# --- struct layouts (rcutils / rmw / rcl, Jazzy) -------------------------------------------------

class _Allocator(ctypes.Structure):
    _fields_ = [('allocate', ctypes.c_void_p), ('deallocate', ctypes.c_void_p),
                ('reallocate', ctypes.c_void_p), ('zero_allocate', ctypes.c_void_p),
                ('state', ctypes.c_void_p)]


class _StringArray(ctypes.Structure):
    _fields_ = [('size', ctypes.c_size_t), ('data', ctypes.POINTER(ctypes.c_char_p)),
                ('allocator', _Allocator)]


class _ContentFilterOptions(ctypes.Structure):
    """``rcl_subscription_content_filter_options_t``, which wraps the rmw struct of this shape."""

    _fields_ = [('filter_expression', ctypes.c_char_p), ('expression_parameters', _StringArray)]


class _Gid(ctypes.Structure):
    _fields_ = [('implementation_identifier', ctypes.c_char_p),
                ('data', ctypes.c_uint8 * 16)]  # RMW_GID_STORAGE_SIZE


class _MessageInfo(ctypes.Structure):
    """``rmw_message_info_t``."""

    _fields_ = [('source_timestamp', ctypes.c_int64), ('received_timestamp', ctypes.c_int64),
                ('publication_sequence_number', ctypes.c_uint64),
                ('reception_sequence_number', ctypes.c_uint64),
                ('publisher_gid', _Gid), ('from_intra_process', ctypes.c_bool)]


class _RequestId(ctypes.Structure):
    _fields_ = [('writer_guid', ctypes.c_uint8 * 16), ('sequence_number', ctypes.c_int64)]


class _ServiceInfo(ctypes.Structure):
    """``rmw_service_info_t``."""

    _fields_ = [('source_timestamp', ctypes.c_int64), ('received_timestamp', ctypes.c_int64),
                ('request_id', _RequestId)]


class _Uint8Array(ctypes.Structure):
    """``rcutils_uint8_array_t``, which is ``rcl_serialized_message_t``."""

    _fields_ = [('buffer', ctypes.POINTER(ctypes.c_uint8)), ('buffer_length', ctypes.c_size_t),
                ('buffer_capacity', ctypes.c_size_t), ('allocator', _Allocator)]


class _ErrorString(ctypes.Structure):
    _fields_ = [('str', ctypes.c_char * 1024)]  # RCUTILS_ERROR_MESSAGE_MAX_LENGTH


# --- library loading ------------------------------------------------------------------------------

def _loaded_library_path(soname: str) -> str:
    """Return the path of ``soname`` as already mapped into this process, else the bare name."""
    try:
        with open('/proc/self/maps') as maps:
            for line in maps:
                path = line.rstrip('\n').split(' ')[-1]
                if os.path.basename(path) == soname:
                    return path
    except OSError:
        pass
    return soname  # let the dynamic loader search LD_LIBRARY_PATH


def _load(soname: str) -> ctypes.CDLL:
    try:
        return ctypes.CDLL(_loaded_library_path(soname))
    except OSError as e:
        raise BindingUnavailable(f'cannot load {soname}: {e}') from e


_rcutils = _load('librcutils.so')
_rcl = _load('librcl.so')
_rcl_action = _load('librcl_action.so')
# cft_action/native/reader/_reader_lock.c: serializes a reader's own filter evaluation with a filter
# change; cft_action/native/reader/_reader_class.c, in the same library: the uuid filter class for
# the process's readers.
_reader_lock = _load(extension_path(READER_LOCK_LIBRARY)
                     or f'{READER_LOCK_LIBRARY} (not built: reinstall with a C compiler)')

_rcutils_get_error_string = _rcutils.rcutils_get_error_string
_rcutils_get_error_string.argtypes = []
_rcutils_get_error_string.restype = _ErrorString
_rcutils_reset_error = _rcutils.rcutils_reset_error
_rcutils_reset_error.argtypes = []
_rcutils_reset_error.restype = None


def take_rcl_error() -> str:
    """Return rcl's current error string and reset it, so that it cannot leak into a later call."""
    message = _rcutils_get_error_string().str.decode('utf-8', 'replace')
    _rcutils_reset_error()
    return message


def _check_rcl_ret(ret: int, func: Any, args: tuple) -> int:
    if ret != RCL_RET_OK:
        name = _RET_NAMES.get(ret, str(ret))
        error = take_rcl_error()
        raise ContentFilterError(f'{func.__name__} returned {name}: '
                                 f'{error or "rcl set no error string"}',
                                 function=func.__name__, ret=ret, rcl_error=error)
    return ret


def _take_failed_is_empty(ret: int, func: Any, args: tuple) -> bool:
    """Return whether a sample was taken; raise rclpy's RCLError for a real failure, as rclpy."""
    if ret in (RCL_RET_SUBSCRIPTION_TAKE_FAILED, RCL_RET_CLIENT_TAKE_FAILED):
        return False
    if ret != RCL_RET_OK:
        raise RCLError(f'{func.__name__} returned {ret}: {take_rcl_error()}')
    return True


def _check_rcutils_ret(ret: int, func: Any, args: tuple) -> int:
    if ret != RCL_RET_OK:
        raise RCLError(f'{func.__name__} returned {ret}: {take_rcl_error()}')
    return ret


def _map_symbol(library: ctypes.CDLL, name: str, restype: Any, argtypes: Sequence[Any],
                errcheck: Optional[Callable] = None) -> Any:
    try:
        func = getattr(library, name)
    except AttributeError as e:
        raise BindingUnavailable(f'symbol {name} not found in {library._name}') from e
    func.restype = restype
    func.argtypes = list(argtypes)
    if errcheck is not None:
        func.errcheck = errcheck
    return func


_void_p = ctypes.c_void_p
_options_p = ctypes.POINTER(_ContentFilterOptions)
_rcl_ret_t = ctypes.c_int

# name: (library, restype, argtypes, errcheck)
_SYMBOLS: dict[str, tuple[ctypes.CDLL, Any, list[Any], Optional[Callable]]] = {
    'rcl_get_zero_initialized_subscription_content_filter_options':
        (_rcl, _ContentFilterOptions, [], None),
    'rcl_subscription_content_filter_options_init':
        (_rcl, _rcl_ret_t,
         [_void_p, ctypes.c_char_p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_char_p), _options_p],
         _check_rcl_ret),
    'rcl_subscription_content_filter_options_fini':
        (_rcl, _rcl_ret_t, [_void_p, _options_p], _check_rcl_ret),
    'rcl_subscription_set_content_filter':
        (_rcl, _rcl_ret_t, [_void_p, _options_p], _check_rcl_ret),
    'rcl_subscription_get_content_filter':
        (_rcl, _rcl_ret_t, [_void_p, _options_p], _check_rcl_ret),
    'rcl_subscription_is_cft_enabled': (_rcl, ctypes.c_bool, [_void_p], None),
    'rcl_subscription_is_valid': (_rcl, ctypes.c_bool, [_void_p], None),
    'rcl_subscription_get_topic_name': (_rcl, ctypes.c_char_p, [_void_p], None),
    'rcl_publisher_get_rmw_handle': (_rcl, _void_p, [_void_p], None),
    'rcl_subscription_get_rmw_handle': (_rcl, _void_p, [_void_p], None),
    # rmw's, found through librcl's dependencies (the wheels link rmw_fastrtps_cpp, apt's
    # rmw_implementation)
    'rmw_get_gid_for_publisher':
        (_rcl, _rcl_ret_t, [_void_p, ctypes.POINTER(_Gid)], _check_rcutils_ret),
    'rcl_action_client_is_valid': (_rcl_action, ctypes.c_bool, [_void_p], None),
    'rcl_client_is_valid': (_rcl, ctypes.c_bool, [_void_p], None),
    'rcl_client_get_service_name': (_rcl, ctypes.c_char_p, [_void_p], None),
    'rcl_take':
        (_rcl, _rcl_ret_t, [_void_p, _void_p, ctypes.POINTER(_MessageInfo), _void_p],
         _take_failed_is_empty),
    'rcl_take_response_with_info':
        (_rcl, _rcl_ret_t, [_void_p, ctypes.POINTER(_ServiceInfo), _void_p],
         _take_failed_is_empty),
    'rcl_take_serialized_message':
        (_rcl, _rcl_ret_t, [_void_p, ctypes.POINTER(_Uint8Array), ctypes.POINTER(_MessageInfo),
                            _void_p], _take_failed_is_empty),
    'rcutils_get_default_allocator': (_rcutils, _Allocator, [], None),
    'rcutils_uint8_array_init':
        (_rcutils, _rcl_ret_t, [ctypes.POINTER(_Uint8Array), ctypes.c_size_t,
                                ctypes.POINTER(_Allocator)], _check_rcutils_ret),
    'rcutils_uint8_array_fini':
        (_rcutils, _rcl_ret_t, [ctypes.POINTER(_Uint8Array)], _check_rcutils_ret),
    'cft_reader_lock_install': (_reader_lock, ctypes.c_int, [], None),
    'cft_reader_lock_error': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_reader_lock_count': (_reader_lock, ctypes.c_ulong, [ctypes.c_int], None),
    'cft_filter_class_install': (_reader_lock, ctypes.c_int, [], None),
    'cft_filter_class_error': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_filter_class_begin': (_reader_lock, None, [ctypes.c_char_p], None),
    'cft_filter_class_end': (_reader_lock, _void_p, [], None),
    'cft_filter_class_verdicts': (_reader_lock, ctypes.c_ulong, [_void_p], None),
    'cft_filter_class_accepts': (_reader_lock, ctypes.c_bool, [ctypes.c_char_p, ctypes.c_char_p],
                                 None),
    'cft_filter_class_rate_mismatches': (_reader_lock, ctypes.c_ulong, [], None),
    'cft_response_filter_install': (_reader_lock, ctypes.c_int, [], None),
    'cft_response_filter_error': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_response_filter_begin': (_reader_lock, None, [], None),
    'cft_response_filter_end': (_reader_lock, _void_p, [ctypes.POINTER(ctypes.c_int)], None),
    'cft_response_filter_refused': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_response_filter_counts':
        (_reader_lock, None, [_void_p, ctypes.POINTER(ctypes.c_ulong)], None),
    'cft_status_acks_install': (_reader_lock, ctypes.c_int, [], None),
    'cft_status_acks_error': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_status_acks_taken': (_reader_lock, ctypes.c_int, [], None),
    'cft_status_acks_refused': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_writer_marks_install': (_reader_lock, ctypes.c_int, [], None),
    'cft_writer_marks_error': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_writer_is_marked': (_reader_lock, ctypes.c_int, [ctypes.c_char_p], None),
    'cft_reader_filter_class':
        (_reader_lock, ctypes.c_int, [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_size_t], None),
    'cft_reader_filters_error': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_status_table_new': (_reader_lock, _void_p, [], None),
    'cft_status_table_free': (_reader_lock, None, [_void_p], None),
    'cft_status_table_sending': (_reader_lock, ctypes.c_int, [_void_p, ctypes.c_char_p], None),
    'cft_status_table_responded':
        (_reader_lock, ctypes.c_int, [_void_p, ctypes.c_char_p, ctypes.c_int], None),
    'cft_status_trim':
        (_reader_lock, ctypes.c_long, [_void_p, _void_p, ctypes.c_size_t, _void_p,
                                       ctypes.POINTER(ctypes.c_size_t), ctypes.c_char_p,
                                       ctypes.c_int], None),
    'cft_status_table_count': (_reader_lock, ctypes.c_ulong, [_void_p, ctypes.c_int], None),
    'cft_status_table_number': (_reader_lock, ctypes.c_ulong, [_void_p], None),
    'cft_fastdds3_layer_refused': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_fastdds3_reader_mark': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_fastdds3_status_reader_mark': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_fastdds3_writer_mark': (_reader_lock, ctypes.c_char_p, [], None),
    'cft_fastdds3_program_mark': (_reader_lock, ctypes.c_char_p, [], None),
    # The Python C API, to reach the C functions that rosidl generates for every message type.
    'PyCapsule_GetName': (ctypes.pythonapi, ctypes.c_char_p, [ctypes.py_object], None),
    'PyCapsule_GetPointer':
        (ctypes.pythonapi, _void_p, [ctypes.py_object, ctypes.c_char_p], None),
}


class _Bound:
    """Attribute access to the declared symbols: ``_lib.rcl_subscription_is_valid(ptr)``."""

    def __init__(self) -> None:
        for name, (library, restype, argtypes, errcheck) in _SYMBOLS.items():
            setattr(self, name, _map_symbol(library, name, restype, argtypes, errcheck))


_lib: Any = _Bound()  # its attributes are the functions of _SYMBOLS, set at run time


# --- content filters on an rcl_subscription_t* ----------------------------------------------------

def _check_subscription(subscription_ptr: int) -> None:
    if not subscription_ptr or not _lib.rcl_subscription_is_valid(subscription_ptr):
        error = take_rcl_error()
        raise ContentFilterError(f'not a valid rcl subscription: {error}',
                                 function='rcl_subscription_is_valid', rcl_error=error)


def reader_lock_status() -> str:
    """Install the reader lock (cft_action/native/reader/_reader_lock.c) if it is not yet; why not,
    or ``''``.

    Without it, Fast DDS 2.14 can crash a process that changes a filter while its reader evaluates
    that filter in a receive thread.
    """
    if _lib.cft_reader_lock_install() == 0:
        return ''
    return (_lib.cft_reader_lock_error() or b'').decode('utf-8', 'replace')


def reader_lock_counts() -> tuple[int, int]:
    """``(evaluations, replacements)``: filter evaluations by readers, and filter swaps, locked."""
    return _lib.cft_reader_lock_count(0), _lib.cft_reader_lock_count(1)


def set_content_filter(subscription_ptr: int, expression: str,
                       parameters: Sequence[str] = (), *,
                       filter_class: Optional[str] = None) -> Optional[int]:
    """Set ``expression`` with ``parameters`` (already DDS literals) on an rcl subscription.

    The reader lock is installed first, so that the reader's own evaluations of the filter do not
    run while Fast DDS replaces it; if it cannot be, a warning says why, once per process.

    :param filter_class: create the subscription's filter with one of the library's own filter
        classes (:data:`UUID_FILTER_CLASS` or :data:`NODE_FILTER_CLASS`,
        cft_action/native/_filter_class.h) instead of DDS-SQL. It takes effect on the first filter,
        which creates the filtered topic; later changes keep its class.
    :return: with ``filter_class``, the filter this call created in this process, for
        :func:`filter_class_verdicts`; None otherwise, or when the preloaded guard created it.
    :raises ContentFilterError: with rcl's error string, or why the class cannot be used.
    """
    _check_subscription(subscription_ptr)
    _install_reader_lock_once()
    if filter_class:
        reason = filter_class_status()
        if reason:
            # Raised before rcl is called: there is no rcl error string, the reason is the part's.
            raise ContentFilterError(
                f'the {filter_class} filter class (built for Fast DDS 2.14 only) cannot be used: '
                f'{reason}', function='cft_filter_class_install')
    encoded = [p.encode() for p in parameters]
    argv = (ctypes.c_char_p * max(1, len(encoded)))(*encoded)
    options = _lib.rcl_get_zero_initialized_subscription_content_filter_options()
    _lib.rcl_subscription_content_filter_options_init(
        subscription_ptr, expression.encode(), len(encoded), argv, ctypes.byref(options))
    try:
        if filter_class:
            _lib.cft_filter_class_begin(filter_class.encode())
        try:
            _lib.rcl_subscription_set_content_filter(subscription_ptr, ctypes.byref(options))
        finally:
            created = _lib.cft_filter_class_end() if filter_class else None
    finally:
        _lib.rcl_subscription_content_filter_options_fini(subscription_ptr, ctypes.byref(options))
    return created or None


#: The library's own filter classes (cft_action/native/_filter_class.h): goal_id.uuid of action
#: feedback, the node of a parameter event, and a rate limit and poll count per writer (whose
#: expressions are not DDS-SQL: cft_action/native/_rate_program.h); and the status reader's
#: (cft_action/native/reader/_status_trim.h), which only this process's readers know.
UUID_FILTER_CLASS = 'CFT_ACTION_UUID'
NODE_FILTER_CLASS = 'CFT_ACTION_NODE'
RATE_FILTER_CLASS = 'CFT_ACTION_RATE'
STATUS_FILTER_CLASS = 'CFT_ACTION_STATUS'


def filter_class_accepts(filter_class: str, expression: str) -> bool:
    """Whether ``filter_class``, one of the library's, compiles ``expression`` in this build
    (the rate class needs the Fast DDS layout of the headers the library was built against)."""
    return _lib.cft_filter_class_accepts(filter_class.encode(), expression.encode())


def rate_layout_mismatches() -> int:
    """Samples that this process's rate filters passed unfiltered because their writer's GUID,
    read at the headers' layout, did not look like one (0 on every stack tested)."""
    return _lib.cft_filter_class_rate_mismatches()


def filter_class_status() -> str:
    """Make the library's filter classes available to this process's readers; why not, or ``''``.

    Only for Fast DDS 2.14 (``libfastrtps.so.2.14``): elsewhere the reason names what is missing.
    """
    return _install_part(_lib.cft_filter_class_install, _lib.cft_filter_class_error)


def _install_part(install: Callable[[], int], error: Callable[[], Optional[bytes]]) -> str:
    """Run a part's ``cft_*_install`` (one of _cftreader's redirections into the loaded Fast DDS
    2.14); return why the part cannot work in this process, or ``''``."""
    if 'fastrtps' not in get_rmw_implementation_identifier():
        return f'{get_rmw_implementation_identifier()} is not rmw_fastrtps'
    if install() < 0:
        reason = (error() or b'').decode('utf-8', 'replace')
        return reason or f'{getattr(install, "__name__", "install")} failed without a reason'
    return ''


def response_filter_begin() -> str:
    """Give the response readers that this thread creates until :func:`response_filter_end` the
    library's filter, which drops other participants' responses in the receive thread
    (cft_action/native/reader/_response_filter.c); return why it cannot, or ``''``."""
    reason = _install_part(_lib.cft_response_filter_install, _lib.cft_response_filter_error)
    if not reason:
        _lib.cft_response_filter_begin()
    return reason


def response_filter_end() -> tuple[Optional[int], int, str]:
    """``(filter, readers, refused)``: the filter those readers share (None if none got it), how
    many got it, and why one did not (``''`` if none was refused)."""
    readers = ctypes.c_int()
    created = _lib.cft_response_filter_end(ctypes.byref(readers))
    return created, readers.value, (_lib.cft_response_filter_refused() or b'').decode(
        'utf-8', 'replace')


def status_acks_begin() -> str:
    """Make the status readers that this thread registers with the library's status filter class
    until :func:`status_acks_end` acknowledge a HEARTBEAT at once, not 5 ms later
    (cft_action/native/reader/_status_acks.c); return why they cannot, or ``''``."""
    reason = _install_part(_lib.cft_status_acks_install, _lib.cft_status_acks_error)
    if not reason:
        _lib.cft_status_acks_taken()
    return reason


def status_acks_end() -> str:
    """``''`` if a status reader registered on this thread since :func:`status_acks_begin`
    acknowledges at once; else why not."""
    if _lib.cft_status_acks_taken() > 0:
        return ''
    return ((_lib.cft_status_acks_refused() or b'').decode('utf-8', 'replace')
            or 'no status reader was registered with the status filter')


def response_filter_counts(created_filter: int) -> tuple[int, int]:
    """``(dropped, passed)``: the responses a filter from :func:`response_filter_end` judged."""
    counts = (ctypes.c_ulong * 2)()
    _lib.cft_response_filter_counts(created_filter, counts)
    return counts[0], counts[1]


def filter_class_verdicts(created_filter: int) -> int:
    """How many samples the filter returned by :func:`set_content_filter` judged in this process:
    every sample that reached the reader (a writer filters for it without a signature)."""
    return _lib.cft_filter_class_verdicts(created_filter)


def _install_writer_marks() -> tuple[bool, str]:
    """Read, from now on, which discovered writers filter for the library's filter classes
    (cft_action/native/reader/_writer_marks.c). Returns whether every writer this process can
    discover will be seen (no participant of the default context existed yet), and why not."""
    reason = _install_part(_lib.cft_writer_marks_install, _lib.cft_writer_marks_error)
    if reason:
        return False, reason
    if ok():
        return False, ('cft_action was first used after rclpy.init(): writers discovered before '
                       'are not known')
    return True, ''


# At the first use of the package's ROS side, which a program normally does before rclpy.init().
_WRITER_MARKS_COMPLETE, WRITER_MARKS_REASON = _install_writer_marks()


def writer_filters(gid: bytes) -> Optional[bool]:
    """Whether the writer with this GID filters for the library's filter classes (a guarded
    writer, which marks its discovery data): True, False, or None when this process may have
    discovered it before it could read the marks (:data:`WRITER_MARKS_REASON`)."""
    if _lib.cft_writer_is_marked(bytes(gid)[:16]):
        return True
    return False if _WRITER_MARKS_COMPLETE else None


# --- the client's Fast DDS 3 layer (cft_action/native/reader/fastdds3/) ---------------------------

#: rmw_fastrtps_cpp::get_datareader(rmw_subscription_t *), public
#: (rmw_fastrtps_cpp/get_subscriber.hpp).
_GET_DATAREADER = '_ZN16rmw_fastrtps_cpp14get_datareaderEP18rmw_subscription_s'


# The layer's symbols, bound where it may be loaded (by library: 'layer', or rmw_fastrtps_cpp's):
# attribute of _Fastdds3Layer: (library, symbol, restype, argtypes); their return codes are the
# callers' to read.
_FASTDDS3_SYMBOLS: dict[str, tuple[str, str, Any, list[Any]]] = {
    'mark_reader':
        ('layer', 'cft_fastdds3_mark_reader', ctypes.c_int32, [_void_p, ctypes.c_char_p]),
    'marked_writers':
        ('layer', 'cft_fastdds3_marked_writers', ctypes.c_int32,
         [_void_p, ctypes.c_char_p, ctypes.POINTER(ctypes.c_int32)]),
    'mark_program':
        ('layer', 'cft_fastdds3_mark_program', ctypes.c_int32,
         [_void_p, ctypes.c_char_p, ctypes.c_char_p]),
    'writer_marked':
        ('layer', 'cft_fastdds3_writer_marked', ctypes.c_int32,
         [_void_p, ctypes.c_char_p, ctypes.c_char_p]),
    'datareader': ('librmw_fastrtps_cpp.so', _GET_DATAREADER, _void_p, [_void_p]),
}


class _Fastdds3Layer:
    """The layer's functions, bound at the first use where it may be loaded; else why not."""

    def __init__(self) -> None:
        self.reason = ''
        self.mark_reader: Any = None
        self.marked_writers: Any = None
        self.mark_program: Any = None
        self.writer_marked: Any = None
        self.datareader: Any = None
        if get_rmw_implementation_identifier() != 'rmw_fastrtps_cpp':
            self.reason = f'{get_rmw_implementation_identifier()} is not rmw_fastrtps_cpp'
            return
        self.reason = (_lib.cft_fastdds3_layer_refused() or b'').decode('utf-8', 'replace')
        if self.reason:
            return
        try:
            libraries = {'layer': _load(extension_path(READER_FASTDDS3_LIBRARY) or
                                        READER_FASTDDS3_LIBRARY),
                         'librmw_fastrtps_cpp.so': _load('librmw_fastrtps_cpp.so')}
            for attribute, (library, name, restype, argtypes) in _FASTDDS3_SYMBOLS.items():
                setattr(self, attribute, _map_symbol(libraries[library], name, restype, argtypes))
        except BindingUnavailable as e:
            self.reason = str(e)


_fastdds3: Optional[_Fastdds3Layer] = None


def _fastdds3_layer() -> _Fastdds3Layer:
    global _fastdds3
    if _fastdds3 is None:
        _fastdds3 = _Fastdds3Layer()
    return _fastdds3


def _datareader(subscription_ptr: int) -> Optional[int]:
    """The subscription's Fast DDS 3 DataReader (the layer is loaded)."""
    _check_subscription(subscription_ptr)
    rmw_subscription = _lib.rcl_subscription_get_rmw_handle(subscription_ptr)
    return _fastdds3_layer().datareader(rmw_subscription) if rmw_subscription else None


def _layer_reader(subscription_ptr: int) -> tuple[Optional[int], str]:
    """The subscription's DataReader where the client's Fast DDS 3 layer may mark it, else None
    and why not."""
    layer = _fastdds3_layer()
    if layer.reason:
        return None, f"the client's Fast DDS 3 layer is off: {layer.reason}"
    reader = _datareader(subscription_ptr)
    return (reader, '') if reader else (None, 'the subscription has no rmw_fastrtps_cpp DataReader')


def mark_own_goals_reader(subscription_ptr: int, status: bool = False) -> str:
    """Ask a guarded Fast DDS 3.3+ server for this feedback reader's own goals' feedback only, or
    (``status``) this status reader's own goals' status changes only: the reader's USER_DATA gets
    the reader mark (native/_filter_class.h, CFT_READER_MARK or CFT_STATUS_READER_MARK;
    DataReader::set_qos). Return why not, or ``''``."""
    reader, why = _layer_reader(subscription_ptr)
    if not reader:
        return why
    mark = _lib.cft_fastdds3_status_reader_mark() if status else _lib.cft_fastdds3_reader_mark()
    ret = _fastdds3_layer().mark_reader(reader, mark)
    return f'DataReader::set_qos returned {ret}' if ret != 0 else ''


def marked_writers(subscription_ptr: int) -> tuple[int, int]:
    """``(marked, matched)``: of the writers the subscription's reader matches, how many say that
    they filter (a guarded Fast DDS 3.3+ server's: CFT_WRITER_MARK); ``(0, -1)`` when Fast DDS
    did not answer. The reader was marked by :func:`mark_own_goals_reader`."""
    reader = _datareader(subscription_ptr)
    marked = ctypes.c_int32()
    matched = _fastdds3_layer().marked_writers(
        reader, _lib.cft_fastdds3_writer_mark(), ctypes.byref(marked)) if (
        reader) else -1
    return marked.value, matched


def mark_reader_program(subscription_ptr: int, filter_class: str, expression: str) -> str:
    """Ask guarded Fast DDS 3.3+ writers to apply ``expression``, a program of the library's
    ``filter_class`` (RATE_FILTER_CLASS or NODE_FILTER_CLASS), to this subscription's reader: its
    USER_DATA's program mark (native/_filter_class.h, CFT_PROGRAM_READER_MARK) becomes it
    (DataReader::set_qos; the writers read it within CFT_FASTDDS3_REREAD_MS). Return why not, or
    ``''``."""
    reader, why = _layer_reader(subscription_ptr)
    if not reader:
        return why
    if ';' in expression:
        return f'the program {expression!r} holds a ";", which ends a mark'
    prefix = _lib.cft_fastdds3_program_mark()
    mark = prefix + f'{filter_class} {expression};'.encode()
    ret = _fastdds3_layer().mark_program(reader, prefix, mark)
    return f'DataReader::set_qos returned {ret}' if ret != 0 else ''


def writer_marked(subscription_ptr: int, gid: bytes) -> Optional[bool]:
    """Whether the writer ``gid``, matched by the subscription's reader (marked by
    :func:`mark_reader_program`), applies the library's marks (a guarded Fast DDS 3.3+ writer's:
    CFT_WRITER_MARK); None when it is not matched (or Fast DDS did not answer)."""
    reader = _datareader(subscription_ptr)
    if not reader:
        return None
    marked = _fastdds3_layer().writer_marked(reader, bytes(gid)[:16],
                                             _lib.cft_fastdds3_writer_mark())
    return None if marked < 0 else bool(marked)


def publisher_gid(publisher: int) -> bytes:
    """The GID of the publisher at this ``rcl_publisher_t *`` (its DataWriter's GUID)."""
    rmw_publisher = _lib.rcl_publisher_get_rmw_handle(publisher)
    if not rmw_publisher:
        raise RCLError(f'rcl_publisher_get_rmw_handle returned NULL: {take_rcl_error()}')
    gid = _Gid()
    _lib.rmw_get_gid_for_publisher(rmw_publisher, ctypes.byref(gid))
    return bytes(gid.data)


def reader_filter_class(gid: bytes) -> Optional[str]:
    """The content filter class of the reader with this GID, from its discovery data
    (cft_action/native/reader/_writer_marks.c): ``'DDSSQL'``, one of the library's classes, ``''``
    for a reader without a filter, or None when this process did not read its data
    (:func:`reader_filters_reason`)."""
    name = ctypes.create_string_buffer(64)
    if _lib.cft_reader_filter_class(bytes(gid)[:16], name, len(name)):
        return name.value.decode('utf-8', 'replace')
    return None


def reader_filters_reason() -> str:
    """Why this process may not know a discovered reader's filter class; ``''`` when it knows
    every reader's."""
    reason = WRITER_MARKS_REASON or (_lib.cft_reader_filters_error() or b'').decode(
        'utf-8', 'replace')
    return reason


_reader_lock_tried = False


def _install_reader_lock_once() -> None:
    global _reader_lock_tried
    if _reader_lock_tried:
        return
    _reader_lock_tried = True
    if 'fastrtps' not in get_rmw_implementation_identifier():
        return  # the hazard is Fast DDS's
    reason = reader_lock_status()
    if reason:
        get_logger('cft_action').warning(
            'filter changes are not serialized with the reader\'s own filter evaluation, which '
            f'can crash this process under Fast DDS: {reason}')


def get_content_filter(subscription_ptr: int) -> tuple[str, list[str]]:
    """Return ``(expression, parameters)`` as the rmw reports them for an rcl subscription."""
    _check_subscription(subscription_ptr)
    options = _lib.rcl_get_zero_initialized_subscription_content_filter_options()
    _lib.rcl_subscription_get_content_filter(subscription_ptr, ctypes.byref(options))
    try:
        expression = (options.filter_expression or b'').decode()
        array = options.expression_parameters
        parameters = [array.data[i].decode() for i in range(array.size)]
    finally:
        _lib.rcl_subscription_content_filter_options_fini(subscription_ptr, ctypes.byref(options))
    return expression, parameters


def is_cft_enabled(subscription_ptr: int) -> bool:
    """Return whether the rmw applies a content filter to this rcl subscription."""
    _check_subscription(subscription_ptr)
    return bool(_lib.rcl_subscription_is_cft_enabled(subscription_ptr))


def subscription_topic_name(subscription_ptr: int) -> Optional[str]:
    """Return the fully qualified topic name of an rcl subscription, or None if it is invalid."""
    return _name_or_none(_lib.rcl_subscription_get_topic_name(subscription_ptr))


def _client_service_name(client_ptr: int) -> Optional[str]:
    return _name_or_none(_lib.rcl_client_get_service_name(client_ptr))


def _name_or_none(name: Optional[bytes]) -> Optional[str]:
    """Decode a name that rcl returned; on NULL, clear the error rcl set and return None."""
    if name is None:
        take_rcl_error()
        return None
    return name.decode()


# --- taking a message with its sample info -------------------------------------------------------

class MessageSupport:
    """The C functions that rosidl generates for one message type, as rclpy uses them.

    :param msg_type: a message class whose type support is imported
        (:func:`rclpy.type_support.check_for_type_support`).
    """

    def __init__(self, msg_type: Any) -> None:
        metaclass = type(msg_type)
        self._create = _capsule_function(
            metaclass._CREATE_ROS_MESSAGE, ctypes.PYFUNCTYPE(ctypes.c_void_p))
        self._destroy = _capsule_function(
            metaclass._DESTROY_ROS_MESSAGE, ctypes.PYFUNCTYPE(None, ctypes.c_void_p))
        self._convert_to_py = _capsule_function(
            metaclass._CONVERT_TO_PY, ctypes.PYFUNCTYPE(ctypes.py_object, ctypes.c_void_p))

    def take(self, take: Callable[[int], bool]) -> Optional[Any]:
        """Call ``take(address of a new C message)``; return the message as Python, or None."""
        message = self._create()
        if not message:
            raise MemoryError('create_ros_message returned NULL')
        try:
            return self._convert_to_py(message) if take(message) else None
        finally:
            self._destroy(message)


def _capsule_function(capsule: Any, prototype: Any) -> Any:
    return prototype(_lib.PyCapsule_GetPointer(capsule, _lib.PyCapsule_GetName(capsule)))


def take_message(subscription_ptr: int,
                 support: MessageSupport) -> tuple[Optional[Any], int]:
    """Take one message from an rcl subscription, as ``rcl_action_take_feedback`` does.

    :return: ``(message, source_timestamp)``: the publisher's clock in nanoseconds, 0 where the
        rmw does not give it; ``(None, 0)`` when no message was there.
    """
    info = _MessageInfo()
    message = support.take(lambda ros_message: _lib.rcl_take(
        subscription_ptr, ros_message, ctypes.byref(info), None))
    return message, (info.source_timestamp if message is not None else 0)


def take_response(client_ptr: int,
                  support: MessageSupport) -> tuple[Optional[int], Optional[Any], int]:
    """Take one response from an rcl client, as ``rcl_action_take_result_response`` does.

    :return: ``(sequence_number, response, source_timestamp)``, the timestamp on the server's
        clock in nanoseconds, 0 where the rmw does not give it; ``(None, None, 0)`` when no
        response was there.
    """
    info = _ServiceInfo()
    response = support.take(lambda ros_response: _lib.rcl_take_response_with_info(
        client_ptr, ctypes.byref(info), ros_response))
    if response is None:
        return None, None, 0
    return info.request_id.sequence_number, response, info.source_timestamp


# --- an action client's status, trimmed to its own goals (_status_trim.c) ------------------------

class StatusTable:
    """The goals of one action client whose status entries go to Python, and the trimming takes.

    A ``GoalStatusArray`` sample is taken serialized and trimmed natively to the entries that can
    change one of this client's goal handles (cft_action/native/reader/_status_trim.c says which);
    the others are never converted to Python. Its methods may be called from any thread.
    """

    #: Bytes of the serialized message's first buffer; rmw grows it for larger samples.
    INITIAL_CAPACITY = 4096

    def __init__(self) -> None:
        self._table = _lib.cft_status_table_new()
        if not self._table:
            raise MemoryError('cft_status_table_new returned NULL')
        allocator = _lib.rcutils_get_default_allocator()
        self._message = _Uint8Array()
        _lib.rcutils_uint8_array_init(ctypes.byref(self._message), self.INITIAL_CAPACITY,
                                      ctypes.byref(allocator))
        self._out = ctypes.create_string_buffer(self.INITIAL_CAPACITY)

    @property
    def filter_expression(self) -> str:
        """The expression of :data:`STATUS_FILTER_CLASS` that names this table, for the status
        subscription: its reader then drops samples that list none of the table's goals."""
        return f'cft_status_table = {_lib.cft_status_table_number(self._table)}'

    def sending(self, goal_uuid: bytes) -> None:
        """A goal's request is about to be sent: its status entries go to Python from now on."""
        if _lib.cft_status_table_sending(self._table, bytes(goal_uuid)) != 0:
            raise MemoryError('cft_status_table_sending: out of memory')

    def responded(self, goal_uuid: bytes, accepted: bool) -> Optional[int]:
        """The goal's response was executed: its goal handle exists, or it was rejected.

        :return: for an accepted goal, the status in the last sample that listed it before, which
            no handle took; else None.
        """
        early = _lib.cft_status_table_responded(self._table, bytes(goal_uuid), int(accepted))
        return None if early < 0 else int(early)

    def take(self, subscription_ptr: int, responding: Optional[bytes],
             all_pending: bool) -> tuple[Optional[bytes], int]:
        """Take one status sample from the rcl subscription and trim it.

        :param responding: the UUID of the goal whose response was taken with the sample, if any.
        :param all_pending: a goal response was taken, and its goal is not known.

        :return: ``(cdr, entries)``: a serialized ``GoalStatusArray`` (with its encapsulation
            header) of the ``entries`` that go to Python; ``(the whole sample, -1)`` when it is not
            plain CDR; ``(None, 0)`` when no sample was there.
        """
        info = _MessageInfo()
        if not _lib.rcl_take_serialized_message(subscription_ptr, ctypes.byref(self._message),
                                                ctypes.byref(info), None):
            return None, 0
        length = self._message.buffer_length
        if len(self._out) < length:
            self._out = ctypes.create_string_buffer(length)
        out_length = ctypes.c_size_t(0)
        entries = _lib.cft_status_trim(self._table, self._message.buffer, length, self._out,
                                       ctypes.byref(out_length), responding, int(all_pending))
        if entries < 0:
            return ctypes.string_at(self._message.buffer, length), -1
        return self._out.raw[:out_length.value], entries

    def counts(self) -> tuple[int, int, int, int]:
        """``(samples, entries, delivered, goals)``: samples trimmed, the entries they listed,
        the entries that went to Python, and the goals whose entries may still go."""
        return (_lib.cft_status_table_count(self._table, 0),
                _lib.cft_status_table_count(self._table, 1),
                _lib.cft_status_table_count(self._table, 2),
                _lib.cft_status_table_count(self._table, 3))

    def __del__(self) -> None:
        # Python frees it when the last reference goes; rcl keeps no pointer into either.
        table, self._table = getattr(self, '_table', None), None
        if table:
            _lib.cft_status_table_free(table)
            _lib.rcutils_uint8_array_fini(ctypes.byref(self._message))


# --- private layout: an action client's result client and subscriptions ---------------------------

# Jazzy's rcl_action_client_impl_t (rcl_action/src/rcl_action/action_client_impl.h, rcl 9.2.x)
# starts with three rcl_client_t (goal, cancel, result; one pointer each), followed by the feedback
# and the status rcl_subscription_t (one pointer each). This has held since Foxy, but it is
# private: every use is verified.
_RESULT_CLIENT_OFFSET = 2 * ctypes.sizeof(ctypes.c_void_p)
#: The subscriptions, by the last part of their topic's name.
_SUBSCRIPTION_OFFSETS = {'feedback': 3 * ctypes.sizeof(ctypes.c_void_p),
                         'status': 4 * ctypes.sizeof(ctypes.c_void_p)}


def _action_client_member(action_client_ptr: int, offset: int, expected: str, kind: str,
                          is_valid: Callable[[int], bool],
                          name_of: Callable[[int], Optional[str]]) -> tuple[Optional[int], str]:
    """Return the address at ``offset`` in the action client's impl if it is the ``expected``."""
    if not action_client_ptr or not _lib.rcl_action_client_is_valid(action_client_ptr):
        return None, f'action client is not valid: {take_rcl_error()}'
    impl = ctypes.c_void_p.from_address(action_client_ptr).value
    if not impl:
        return None, 'action client has no implementation'
    candidate = impl + offset
    # Under the expected layout the candidate is an rcl_subscription_t or rcl_client_t { impl* };
    # under another one it is still a pointer-sized field inside rcl's own allocation, so reading
    # it cannot fault.
    if not is_valid(candidate):
        return None, (f'layout check failed: no valid {kind} at the expected offset '
                      f'({take_rcl_error()})')
    found = name_of(candidate)
    if found != expected:
        return None, f'layout check failed: found {kind} {found!r}, expected {expected!r}'
    return candidate, ''


def action_subscription(action_client_ptr: int, resolved_action_name: str,
                        topic: str) -> tuple[Optional[int], str]:
    """Locate the feedback or the status subscription inside an ``rcl_action_client_t``.

    :param action_client_ptr: address of the ``rcl_action_client_t``
        (the ``pointer`` of the action client's rcl handle).
    :param resolved_action_name: the fully qualified action name, after remapping.
    :param topic: ``'feedback'`` or ``'status'``: the subscription of
        ``<action>/_action/<topic>``.
    :return: ``(address, '')`` when the layout check passed, or ``(None, reason)`` when it did not;
        in that case nothing at the guessed address was touched as a subscription.
    """
    return _action_client_member(
        action_client_ptr, _SUBSCRIPTION_OFFSETS[topic],
        f'{resolved_action_name}/_action/{topic}', 'topic',
        _lib.rcl_subscription_is_valid, subscription_topic_name)


def action_feedback_subscription(action_client_ptr: int,
                                 resolved_action_name: str) -> tuple[Optional[int], str]:
    """:func:`action_subscription` of the feedback topic."""
    return action_subscription(action_client_ptr, resolved_action_name, 'feedback')


def action_result_client(action_client_ptr: int,
                         resolved_action_name: str) -> tuple[Optional[int], str]:
    """Locate the result client inside an ``rcl_action_client_t``.

    As :func:`action_subscription`, for the ``rcl_client_t`` of ``get_result``.
    """
    return _action_client_member(
        action_client_ptr, _RESULT_CLIENT_OFFSET,
        resolved_action_name + '/_action/get_result', 'service',
        _lib.rcl_client_is_valid, _client_service_name)

