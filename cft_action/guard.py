# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The server guard: an ``LD_PRELOAD`` shim that makes Fast DDS writer-side filtering race-free.

With Fast DDS 2.14 (Jazzy) and 3.2 (Kilted), a content filter that a *client* changes, or a
filtered reader that goes away, can crash the process that owns the writer (the action server):
the discovery thread replaces the writer's per-reader filters without the writer's lock while a
publish evaluates them (eProsima/Fast-DDS issue 4878). No client-side setting prevents it.

The guard is a small C library, built with this package from ``cft_action/native/guard/`` and the
filter classes in ``cft_action/native/`` (``_guard_families.h`` lists the parts; setup.py builds
them, and takes the Fast DDS layouts they read from the Fast DDS headers it finds). Preloaded into
the **server** process, it serializes each writer's publish path with the discovery path that
changes that writer's filters. The server's code does not change::

    cft-action guard -- python my_action_server.py

or, from Python, ``subprocess.Popen(cmd, env=cft_action.guard.environment())``.

Where it knows the Fast DDS, it also sends each of an action's goal, cancel and result replies only
to the response readers of the participant that sent the request (the others' take would discard
it): see :func:`reply_counts`; ``CFT_GUARD_REPLIES=off`` sends every reply to every client, as
rmw_fastrtps does. On Fast DDS 3.3+ (Lyrical) it does so through the writers' public sample
prefilter, where the package was built against those headers: see :func:`prefilter`; there it
also sends each of this library's clients only its own goals' feedback (:func:`feedback_counts`,
``CFT_GUARD_FEEDBACK=off``).

It only locks on a Fast DDS it knows (``libfastrtps.so.2.14``, ``libfastdds.so.3.6``,
``libfastdds.so.3.2``). On any other version it calls straight through and prints one line on
stderr saying that it is inactive and why.
Set ``CFT_GUARD_DEBUG=1`` to see what it does.
"""

from __future__ import annotations

import ctypes
import os
import re
from typing import Mapping, Optional

from cft_action._native import extension_path, GUARD_LIBRARY
from cft_action.errors import CftActionError

__all__ = ['GuardUnavailable', 'library_path', 'is_active', 'status', 'call_counts',
           'filter_counts', 'layout', 'prefilter', 'writer_limits', 'reply_counts',
           'status_counts', 'feedback_counts', 'environment', 'READER_FILTERS_ENV', 'REPLIES_ENV',
           'STATUS_ENV', 'FEEDBACK_ENV']

#: Environment variable with the number of filtered readers that each writer of a guarded process
#: filters for (1 to 4063; default 1024; Fast DDS's own limit is 32).
READER_FILTERS_ENV = 'CFT_ACTION_READER_FILTERS'

#: Name of the extension module that setup.py builds from the guard's C files.
_MODULE = GUARD_LIBRARY

# State codes of cft_guard_state() in _guard.c.
_ARMED, _ACTIVE, _INACTIVE = 0, 1, 2


class GuardUnavailable(CftActionError, RuntimeError):
    """The guard library was not built, or its path cannot be put into ``LD_PRELOAD``."""


def library_path() -> str:
    """Return the absolute path of the built guard library (the file to ``LD_PRELOAD``).

    :raises GuardUnavailable: when the package was installed without building it.
    """
    path = extension_path(_MODULE)
    if path is not None:
        return path
    raise GuardUnavailable(
        f'the guard library ({_MODULE}*.so) was not found next to {__file__}; '
        'reinstall cft-action with a C compiler available (pip install .)')


_process: Optional[ctypes.CDLL] = None  # _preloaded's handle, once found


def _preloaded() -> Optional[ctypes.CDLL]:
    """Return a handle to this process's global scope if the guard's C API is visible in it.

    Found once: a library in the global scope stays there (a preload, or a later RTLD_GLOBAL
    load, which is why an absent guard is looked for again at each call).
    """
    global _process
    if _process is not None:
        return _process
    try:
        process = ctypes.CDLL(None)
        process.cft_guard_state  # noqa: B018  (lookup only)
    except (OSError, AttributeError):
        return None
    process.cft_guard_state.argtypes = []
    process.cft_guard_state.restype = ctypes.c_int
    process.cft_guard_reason.argtypes = []
    process.cft_guard_reason.restype = ctypes.c_char_p
    process.cft_guard_filter_layout_report.argtypes = []
    process.cft_guard_filter_layout_report.restype = ctypes.c_char_p
    _process = process
    return process


def _counters(symbol: str, names: tuple[str, ...]) -> dict[str, int]:
    """The guard's counters ``symbol(0)``, ``symbol(1)``, ... as ``names``; {} if not preloaded."""
    process = _preloaded()
    if process is None:
        return {}
    count = getattr(process, symbol)
    count.argtypes = [ctypes.c_int]
    count.restype = ctypes.c_ulong
    return {name: int(count(i)) for i, name in enumerate(names)}


def is_active() -> bool:
    """Return True when this process has the guard preloaded and it is protecting Fast DDS.

    True while the guard waits for Fast DDS to load (before the first node is created) and once it
    interposes a Fast DDS version it knows. False when the guard is not preloaded, when the loaded
    Fast DDS is a version it does not know (it then calls straight through), or when it was loaded
    after Fast DDS; :func:`status` says which.
    """
    process = _preloaded()
    return process is not None and process.cft_guard_state() != _INACTIVE


def status() -> str:
    """Return one line describing the guard in this process.

    For example ``'active: libfastrtps.so.2.14 (/path/libfastrtps.so.2.14)'``.

    Starts with ``'active'``, ``'armed'`` (preloaded, no Fast DDS loaded yet), ``'inactive'`` or
    ``'not preloaded'``.
    """
    process = _preloaded()
    if process is None:
        return 'not preloaded: cft_guard_state is not in the global symbol scope'
    return process.cft_guard_reason().decode('utf-8', 'replace')


def call_counts() -> dict[str, int]:
    """Return how often the guard's interposed Fast DDS members ran in this process.

    Keys: ``perform_create_new_change``, ``process_reader_filter_info``, ``remove_reader_filter``
    and ``nested_unlocked`` (nested writes that went on without their lock to avoid a deadlock).
    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_call_count', ('perform_create_new_change',
                                               'process_reader_filter_info',
                                               'remove_reader_filter', 'nested_unlocked'))


#: The counters of cft_guard_filter_count() in _guard_filter.c, in its order.
FILTER_COUNTERS = ('uuid_verdicts', 'fastdds_verdicts', 'compiled', 'not_compiled', 'dropped',
                   'evicted', 'foreign_instance', 'verified', 'mismatches', 'kept', 'left',
                   'relevance_verdicts', 'refused', 'unknown_classes')


def filter_counts() -> dict[str, int]:
    """Return the counters of the guard's filter verdicts in this process.

    The guard answers a writer-side filter whose every term is ``goal_id.uuid[i] = value`` from the
    sample's UUID bytes, instead of letting Fast DDS deserialize the sample once per filtered
    reader. Keys:

    - ``uuid_verdicts``: verdicts given from the UUID bytes;
    - ``fastdds_verdicts``: verdicts left to Fast DDS (other filters, or none compiled);
    - ``compiled`` / ``not_compiled``: reader filters the guard compiled, or left to Fast DDS;
    - ``dropped``, ``evicted``, ``foreign_instance``: compiled filters forgotten because their
      reader went away or changed unseen, because the table was full, or because a verdict came for
      another filter instance;
    - ``verified`` / ``mismatches``: with ``CFT_GUARD_VERIFY=1``, verdicts also asked of Fast DDS,
      and how many of them disagreed (0, or the guard is wrong);
    - ``kept``: readers of the library's filter classes that the guard keeps itself, out of Fast
      DDS's filter collection, so that no filter signature is written for them (each reader once
      per writer and filter change); ``left``: such readers left to Fast DDS (the writer's virtual
      call would not reach the guard, or the guard's table was full); ``relevance_verdicts``: the
      verdicts given for kept readers when the writer asked whether a sample is relevant to them.
      ``CFT_GUARD_KEEP_READERS=0`` leaves every reader to Fast DDS;
    - ``refused``: remote readers' filters of the library's classes whose expression is outside the
      class's grammar (no filter is kept: the reader gets every sample, as a plain one);
      ``unknown_classes``: remote readers' filter classes named like the library's (``CFT_ACTION``
      in any case) that are none of them. The first of each is said once on stderr.

    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_filter_count', FILTER_COUNTERS)


def layout() -> str:
    """Return what the guard knows about the Fast DDS layout its filter verdicts read.

    The layout comes from the Fast DDS headers the guard was built against, and is checked on the
    loaded library's own reader discovery data before it is used: for example ``'the layout of the
    headers of Fast DDS 2.14.5 (HAVE_SECURITY 0) in ..., moved 8 bytes later from m_guid on,
    checked on the loaded Fast DDS (HAVE_SECURITY 1): ...'``. ``'not checked yet: ...'`` until a
    filtered reader was seen; an empty string when the guard is not preloaded.
    """
    process = _preloaded()
    if process is None:
        return ''
    return process.cft_guard_filter_layout_report().decode('utf-8', 'replace')


def prefilter() -> str:
    """Return the state of the guard's Fast DDS 3 layer, which routes an action's replies and
    feedback with the writers' public sample prefilter (Fast DDS 3.3+, Lyrical): ``'on: <its
    library>, built with <headers>'``, or ``'off: <why>'`` (``CFT_GUARD_REPLIES`` and
    ``CFT_GUARD_FEEDBACK`` off, not built against Fast DDS 3.3+ headers, another Fast DDS loaded,
    another rmw, or no action endpoint created yet). Decided at the first action service or
    feedback publisher of a process of Fast DDS 3, and said once on stderr when off. An empty
    string when the guard is not preloaded.
    """
    process = _preloaded()
    if process is None:
        return ''
    state = process.cft_guard_prefilter_state
    state.argtypes = []
    state.restype = ctypes.c_char_p
    return state().decode('utf-8', 'replace')


#: The counters of cft_guard_filter_class_count() in _guard.c, in its order.
FILTER_CLASS_COUNTERS = ('lookups', 'filters', 'verdicts', 'changes')


def filter_class_counts() -> dict[str, int]:
    """Return what this process's writers did with the library's own filter classes.

    A client's feedback filter uses one of them (``CFT_ACTION_UUID``), a ParameterEventHandler's
    node filter the other (``CFT_ACTION_NODE``; cft_action/native/_filter_class.h); only a guarded
    process knows them: ``lookups`` counts the times Fast DDS asked the guard for
    its factory, ``filters`` the filters created (one per filtered reader and writer, and per
    reader of this process), ``verdicts`` the samples they judged, ``changes`` the filters
    created or changed in place: one per filter event. ``{}`` without the guard.
    """
    return _counters('cft_guard_filter_class_count', FILTER_CLASS_COUNTERS)


#: The counters of cft_guard_writer_qos_count() in _guard_writer_qos.c, in its order.
WRITER_QOS_COUNTERS = ('raised', 'left', 'reader_filters', 'marked')


def writer_limits() -> dict[str, int]:
    """Return how many filtered readers the writers of this process filter for.

    A Fast DDS 2.14 writer keeps the filters of at most 32 readers; a filtered reader beyond them
    receives every sample and filters it itself. The guard raises that limit to
    ``CFT_ACTION_READER_FILTERS`` (default 1024) in the QoS of every writer that rmw_fastrtps
    creates, where it knows the Fast DDS (see :func:`status`). Keys:

    - ``raised``: writers created with the raised limit;
    - ``left``: writers left at 32, because the guard does not know this Fast DDS or its QoS did not
      hold the expected default (the guard says why on stderr, once);
    - ``reader_filters``: the limit that raised writers get (32: not raised);
    - ``marked``: writers whose discovery data says that they filter for the library's filter
      classes (``cft_action=filters;`` in their USER_DATA), which is how a client tells where its
      feedback is filtered (``filtered_in``) now that their samples carry no filter signature.

    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_writer_qos_count', WRITER_QOS_COUNTERS)


#: The counters of cft_guard_heartbeat_count() in _guard_heartbeats.c, in its order.
HEARTBEAT_COUNTERS = ('narrowed', 'widened', 'gaps_deferred', 'gaps_passed', 'piggyback_spaced',
                      'gaps_merged', 'merges_dropped', 'piggyback_merged')


def heartbeat_counts() -> dict[str, int]:
    """Return what the guard did with its writers' HEARTBEATs and GAPs to filtered readers.

    A Fast DDS 2.14 writer heartbeats every reader at each write while its history is full (rclpy's
    default keep-last 10 nearly always is), and 2.14.6 also sends each filtered reader a GAP at
    each write it is not in: a datagram per sample to readers that receive none of it. The guard
    keeps that HEARTBEAT with the DATA, to the DATA's readers (``CFT_GUARD_HEARTBEAT_ALL_MS``:
    ``never``, the default, but for a status writer's every 10 ms; a number of ms lets it through
    to all readers at most that often per writer; ``off``: as Fast DDS), and leaves those GAPs
    to the reader's next sample, NACK or periodic heartbeat (``CFT_GUARD_DEFER_GAPS=0``: as Fast
    DDS). In a write that judged a reader the guard keeps and a plain one (not a status
    writer's), the piggyback HEARTBEAT goes at most every 10 ms per writer
    (``CFT_GUARD_PIGGYBACK_MS``; ``off``: every write). In a write whose change goes to one reader
    (not a status writer's), the personal GAP and HEARTBEAT that Fast DDS sends a reader with a run
    of filtered-out changes before its DATA, in a datagram of their own, go in the DATA's
    datagram, and that DATA's piggyback HEARTBEAT, the same again, is left out
    (``CFT_GUARD_MERGE_GAPS=0``: as Fast DDS). On Fast DDS 3.6 (Lyrical) all but the spacing act,
    in the writes of the feedback and status writers routed to the library's clients
    (:func:`feedback_counts`), which 3.6 sends such HEARTBEATs and GAPs alike.
    Keys:

    - ``narrowed``: piggyback HEARTBEATs that went to the DATA's readers only;
    - ``widened``: those let through to all readers;
    - ``gaps_deferred``: per-write GAPs left for later (0 on 2.14.5, which sends none);
    - ``gaps_passed``: GAPs of the other kinds, sent as Fast DDS sends them;
    - ``piggyback_spaced``: piggyback HEARTBEATs left out, within 10 ms of the writer's last;
    - ``gaps_merged``: personal GAPs sent in their DATA's datagram;
    - ``merges_dropped``: of those held back, dropped because no DATA of theirs followed (the
      reader asks for the run with a NACK; always 0 but after an exception);
    - ``piggyback_merged``: piggyback HEARTBEATs left out after a merged one in the same datagram.

    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_heartbeat_count', HEARTBEAT_COUNTERS)


def closed_readers(writer_gid: bytes) -> Optional[int]:
    """Return how many readers matched by this process's writer ``writer_gid`` (16 bytes) a
    message written now would not reach because of the library's rate and poll filters: a rate
    window still closed, a poll with no message left.

    None when the guard is not preloaded, or does not keep its writers' filters (a Fast DDS other
    than 2.14).
    """
    process = _preloaded()
    if process is None:
        return None
    closed = process.cft_guard_closed_readers
    closed.argtypes = [ctypes.c_char_p]
    closed.restype = ctypes.c_int
    count = closed(bytes(writer_gid)[:16])
    return None if count < 0 else count


#: The counters of cft_guard_reply_count() in _guard_replies.c, in its order.
REPLY_COUNTERS = ('marked', 'withheld', 'passed', 'implausible', 'full')

#: Environment variable that turns the reply filter off (``off`` or ``0``).
REPLIES_ENV = 'CFT_GUARD_REPLIES'


def reply_counts() -> dict[str, int]:
    """Return what the guard did with this process's action replies.

    rmw_fastrtps writes every goal, cancel and result reply to every client's response reader, and
    each client's take discards the others' replies. The guard sends a reply only to the readers of
    the participant whose request it answers (named by the reply's related sample identity); the
    others get a GAP for it (cft_action/native/guard/_guard_replies.c). ``CFT_GUARD_REPLIES=off``
    turns that off. Keys:

    - ``marked``: reply writers (``rr/.../_action/{send_goal,cancel_goal,get_result}Reply``) whose
      replies go to the requesting participant only;
    - ``withheld``: verdicts that kept a reply from a reader of another participant;
    - ``passed``: verdicts for readers of the requesting participant (the reply goes to them);
    - ``implausible``: replies whose related identity did not read as rmw_fastrtps writes it (sent
      to every reader, as without the guard; 0, or the layout is not the one expected);
    - ``full``: reply writers left unmarked because the guard's table was full.

    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_reply_count', REPLY_COUNTERS)


#: The counters of cft_guard_feedback_count() in _guard_feedback.c, in its order.
FEEDBACK_COUNTERS = ('writers', 'verdicts', 'withheld', 'unknown', 'malformed')

#: Environment variable that turns the Fast DDS 3 feedback prefilter off (``off`` or ``0``).
FEEDBACK_ENV = 'CFT_GUARD_FEEDBACK'


def feedback_counts() -> dict[str, int]:
    """Return what the guard did with this process's action feedback on Fast DDS 3.3+.

    There, an action's feedback writer gets a sample prefilter (public Fast DDS API) that sends the
    library's clients, which mark their feedback reader's USER_DATA, only the feedback of the goals
    their participant requested; every other reader gets every sample
    (cft_action/native/guard/_guard_feedback.c). ``CFT_GUARD_FEEDBACK=off`` turns that off, and
    ``RMW_FASTRTPS_PUBLICATION_MODE=ASYNCHRONOUS`` keeps it off (said once on stderr): the GAPs and
    HEARTBEATs of withheld samples are kept cheap on the writing thread only
    (:func:`heartbeat_counts`). On Fast DDS 2.14 feedback is filtered through the content filter
    classes instead (:func:`filter_counts`) and these stay 0. Keys:

    - ``writers``: feedback writers given the prefilter (and the mark that says so);
    - ``verdicts``: samples judged for marked readers; of those, ``withheld`` went not to the
      reader (another participant's goal), ``unknown`` went to it because the goal's requester
      was not recorded, ``malformed`` because the sample did not read as plain CDR.

    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_feedback_count', FEEDBACK_COUNTERS)


#: The counters of cft_guard_program_count() in _guard_programs.c, in its order.
PROGRAM_COUNTERS = ('writers', 'verdicts', 'withheld', 'refused', 'malformed')

#: Environment variable that turns the readers' programs off in guarded writers (``off`` or ``0``).
PROGRAMS_ENV = 'CFT_GUARD_PROGRAMS'


def program_counts() -> dict[str, int]:
    """Return what this process's writers did with the programs their readers mark, on Fast DDS
    3.3+.

    There, every writer but an action's feedback and status writers gets a sample prefilter
    (public Fast DDS API) that applies, to each reader whose USER_DATA holds a program mark (the
    library's rate-limited and polled subscriptions, and its ParameterEventHandler, where their
    filter classes cannot be used), that program: a rate limit and polls, or a list of nodes
    (cft_action/native/guard/_guard_programs.c). ``CFT_GUARD_PROGRAMS=off`` turns it off. On Fast
    DDS 2.14 the classes are content filters instead (:func:`filter_class_counts`). Keys:

    - ``writers``: writers given the prefilter (and the mark that says so);
    - ``verdicts``: samples judged for marked readers; of those, ``withheld`` went not to it;
      ``malformed``: parameter events passed because their node could not be read;
    - ``refused``: marks outside the classes' grammars (such a reader gets every sample).

    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_program_count', PROGRAM_COUNTERS)


#: The counters of cft_guard_status_count() in _guard_status.c, in its order.
STATUS_COUNTERS = ('requests', 'implausible', 'verdicts', 'changed', 'owed', 'withheld',
                   'unknown', 'malformed', 'resets', 'kept', 'deferred', 'heartbeat_periods',
                   'contested')

#: Environment variable that turns the status filter off (``off`` or ``0``).
STATUS_ENV = 'CFT_GUARD_STATUS'


def status_counts() -> dict[str, int]:
    """Return what the guard did with this process's action status samples.

    An action server's status writer sends every status sample, which lists every goal, to every
    client. The guard sends a sample to a client of this library only when it changes the status of
    a goal that the client's participant requested, or when the client had been passed the sample
    before it and had not acknowledged it when it was replaced (cft_action/native/guard/
    _guard_status.c). Plain clients get every sample. ``CFT_GUARD_STATUS=off`` turns it off. On Fast
    DDS 3.3+ (Lyrical) the status writer's public sample prefilter asks the same verdict for the
    clients' marked status readers (owed samples deferred, the 100 ms heartbeat set through the
    writer's QoS), and ``kept`` counts routed status writers. Keys:

    - ``requests``: goal requests taken, recorded with the participant that sent them;
    - ``implausible``: goal requests whose header did not name a user endpoint (not recorded);
    - ``verdicts``: verdicts for the clients' status readers; of those, ``changed`` passed a
      sample that changes one of the reader's goals, ``owed`` one owed to it, ``withheld`` none;
    - ``unknown``: entries of goals whose requester was not recorded (they go to every reader);
    - ``malformed``: samples that did not read as a GoalStatusArray (passed);
    - ``resets``: times the record of requesters was full (32,768 goals) and started anew;
    - ``kept``: status readers the guard keeps (they are in ``filter_counts()['kept']`` too, and
      their verdicts in its ``relevance_verdicts``);
    - ``deferred``: owed samples not sent with the write: the client asks for the writer's latest
      when a HEARTBEAT shows it one it lacks (``CFT_GUARD_DEFER_OWED=0`` sends them at once);
    - ``heartbeat_periods``: status writers that heartbeat every 100 ms while a client has not
      acknowledged, instead of Fast DDS's 3 s (``CFT_GUARD_STATUS_HEARTBEAT_MS``: the period, or
      ``off``);
    - ``contested``: goal requests for a goal UUID that another participant had requested (the
      first requester keeps the goal's status; the first such request is said once on stderr).

    An empty dict when the guard is not preloaded.
    """
    return _counters('cft_guard_status_count', STATUS_COUNTERS)


def environment(env: Optional[Mapping[str, str]] = None) -> dict[str, str]:
    """Return a copy of ``env`` (default: ``os.environ``) with the guard first in ``LD_PRELOAD``.

    Entries already in ``LD_PRELOAD`` are kept after it; the guard is not added twice. Pass the
    result as ``env=`` to :class:`subprocess.Popen` for the process that runs the action server.

    :raises GuardUnavailable: when the library is missing, or its path contains a character that
        ``LD_PRELOAD`` cannot carry (a space or a colon).
    """
    result = dict(os.environ if env is None else env)
    path = library_path()
    if re.search(r'[\s:]', path):
        raise GuardUnavailable(f'LD_PRELOAD cannot carry a path with spaces or colons: {path!r}')
    # ld.so splits LD_PRELOAD on spaces and colons.
    others = [entry for entry in re.split(r'[\s:]+', result.get('LD_PRELOAD', ''))
              if entry and os.path.realpath(entry) != os.path.realpath(path)]
    result['LD_PRELOAD'] = ':'.join([path, *others])
    return result
