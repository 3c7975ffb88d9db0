"""Plots of load results, with matplotlib's file-only Agg backend (no display needed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from harness.load import phase_label

#: One colour per configuration, the same in every plot.
COLOURS = {'rclpy': '#7f7f7f', 'client': '#1f77b4', 'goals': '#2ca02c', 'upstream': '#d62728'}
#: The colour of a configuration whose server ran without the guard.
UNGUARDED_COLOURS = {'rclpy': '#c7c7c7', 'client': '#9ecae1', 'goals': '#a1d99b',
                     'upstream': '#fc9272'}


#: The top of the demo's panel of ratios to plain rclpy.
RATIO_TOP = 1.25


def phase_colour(phase: dict[str, Any]) -> str:
    """The colour of ``phase``: its configuration's, lighter when its server was unguarded."""
    return (COLOURS if phase.get('guarded', True) else UNGUARDED_COLOURS)[phase['config']]


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def save(fig: Any, path: Path) -> Path:
    """Lay out ``fig``, write it to ``path`` (creating its folder) and close it."""
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    pyplot().close(fig)
    return path


def finish_axes(ax: Any, xlabel: str, ylabel: str, title: str, xbase: int = 10,
                ylog: bool = True) -> None:
    """Label a panel with logarithmic axes (x in ``xbase``; y unless ``ylog`` is False), a grid
    and a legend."""
    ax.set_xscale('log', base=xbase)
    if ylog:
        ax.set_yscale('log')
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which='both', alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)


def demo_figure(result: dict[str, Any], path: Path) -> Path:
    """Write the one-load-point comparison of the demo to ``path`` (PNG); return the path."""
    plt = pyplot()
    phases = result['phases']
    spec = result['spec']
    labels = [phase_label(p).replace(' ', '\n', 1).replace(', ', ',\n') for p in phases]
    colours = [phase_colour(p) for p in phases]
    s = [p['summary'] for p in phases]
    x = range(len(phases))
    fig, axes = plt.subplots(2, 4, figsize=(18, 8.2))

    ax = axes[0][0]
    own = [v['own_per_client'] for v in s]
    foreign = [v['foreign_per_client'] for v in s]
    ax.bar(x, own, color=colours, label='own')
    ax.bar(x, foreign, bottom=own, color=colours, alpha=0.35, hatch='//', label='foreign')
    ax.set_title('feedback messages taken per client\n(solid: own, hatched: foreign)')
    _annotate(ax, x, [o + f for o, f in zip(own, foreign)],
              [f'{f:.0f} foreign' for f in foreign])

    ax = axes[0][1]
    kb = [v['bytes_per_client'] / 1000 for v in s]
    ax.bar(x, kb, color=colours)
    ax.set_yscale('log')
    ax.axhline(s[0]['own_feedback_bytes_per_client'] / 1000, color='k', ls='--', lw=1,
               label='own feedback payload (the floor)')
    ax.legend(loc='upper right', fontsize=8)
    method = 'rx_bytes per client interface' if result['bytes_method'] == 'netns' \
        else 'ESTIMATED: messages x size'
    ax.set_title(f'kB received per client, log\n({method})')
    _annotate(ax, x, kb, [f'{v:.0f}' for v in kb])

    _bar_panel(axes[0][2], x, [v['client_cpu_s'] for v in s], colours,
               'client CPU seconds (user + system,\nall client processes)', '.1f')

    ax = axes[1][0]
    width = 0.38
    p50 = [v['latency_p50_ms'] or 0 for v in s]
    p99 = [v['latency_p99_ms'] or 0 for v in s]
    ax.bar([i - width / 2 for i in x], p50, width, color=colours, label='p50')
    ax.bar([i + width / 2 for i in x], p99, width, color=colours, alpha=0.45, label='p99')
    ax.set_yscale('log')
    ax.set_title('feedback latency, publish to callback (ms, log)\n(left: p50, right: p99)')
    for i, (a, b) in enumerate(zip(p50, p99)):
        ax.text(i - width / 2, a, _short(a), ha='center', va='bottom', fontsize=8)
        ax.text(i + width / 2, b, _short(b), ha='center', va='bottom', fontsize=8)
    ax.margins(y=0.15)

    _bar_panel(axes[1][1], x, [v['updates_per_goal'] for v in s], colours,
               'filter updates per goal\n(each one an event at the server\'s writer)', '.2f')
    _bar_panel(axes[0][3], x, [v['server_msgs_per_s'] or 0 for v in s], colours,
               'server: feedback published per second\n(go to its last goal; higher is better)',
               '.0f')
    _bar_panel(axes[1][3], x, [v['server_cpu_ms_per_msg'] or 0 for v in s], colours,
               'server: CPU ms per feedback message\n(user + system; lower is better)', '.3f')

    ax = axes[1][2]
    ratios = [p['summary'].get('ratio_to_plain') or {} for p in phases]
    keys = ('foreign', 'bytes', 'cpu', 'p99', 'server_cpu')
    width = 0.8 / max(1, len(phases))
    for j, (phase, r) in enumerate(zip(phases, ratios)):
        positions = [k + (j - (len(phases) - 1) / 2) * width for k in range(len(keys))]
        values = [r.get(k) or 0 for k in keys]
        ax.bar(positions, values, width, color=phase_colour(phase), label=phase_label(phase))
        if phase['config'] != 'rclpy':
            for position, value in zip(positions, values):  # a bar above the axis: at its top
                ax.text(position, min(value, RATIO_TOP), f'{value:.2f}', ha='center',
                        va='bottom' if value < RATIO_TOP else 'top', fontsize=7, rotation=90)
    ax.set_xticks(range(len(keys)), ['foreign\nmsgs', 'bytes', 'client\nCPU', 'p99\nlatency',
                                     'server\nCPU/msg'], fontsize=8)
    ax.set_ylim(0, RATIO_TOP)
    ax.axhline(1.0, color='k', lw=0.8)
    ax.set_title('ratio to plain rclpy (lower is better)')
    ax.legend(fontsize=8, loc='upper right')

    for ax in (*axes[0], axes[1][0], axes[1][1], axes[1][3]):  # the ratios have their own ticks
        ax.set_xticks(list(x), labels, fontsize=9)
    first = s[0]
    servers = ('one guarded server' if all(p.get('guarded', True) for p in phases)
               else 'a guarded server, then an unguarded one')
    fig.suptitle(f"{spec['clients']} client processes x {spec['goals']} goals, "
                 f"{spec['order']} feedback messages per goal at {spec['rate_hz']:g} Hz "
                 f"({first['feedback_message_bytes']} B each), {servers}; "
                 f"all feedback per configuration: {first['all_feedback']}", fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _short(value: float) -> str:
    return f'{value:.0f}' if value >= 100 else f'{value:.3g}'


def _bar_panel(ax: Any, x: Any, values: list[float], colours: Any, title: str,
               number_format: str) -> None:
    ax.bar(x, values, color=colours)
    ax.set_title(title)
    _annotate(ax, x, values, [format(v, number_format) for v in values])


def _annotate(ax: Any, x: Any, heights: list[float], texts: list[str]) -> None:
    for i, (h, t) in enumerate(zip(heights, texts)):
        ax.text(i, h, t, ha='center', va='bottom', fontsize=8)
    ax.margins(y=0.15)


#: The kinds of received bytes of a packet capture (``harness.capture.CATEGORIES``), with
#: their colours.
CATEGORY_COLOURS = {'feedback data': '#1f77b4', 'feedback gap/heartbeat': '#aec7e8',
                    'status': '#ff7f0e', 'discovery': '#2ca02c', 'other': '#c7c7c7'}


def stacked_categories(ax: Any, labels: list[str], rows: list[dict[str, float]],
                       total_format: str = '.2f') -> None:
    """Stacked bars on ``ax``, one per label: ``rows[i]`` maps each capture category to a height.

    The total is written on top of each bar; the categories of :data:`CATEGORY_COLOURS` stack in
    that order, with a legend.
    """
    x = list(range(len(labels)))
    bottoms = [0.0] * len(labels)
    for category, colour in CATEGORY_COLOURS.items():
        heights = [row.get(category, 0.0) for row in rows]
        ax.bar(x, heights, bottom=bottoms, color=colour, label=category)
        bottoms = [b + h for b, h in zip(bottoms, heights)]
    for i, total in enumerate(bottoms):
        ax.text(i, total, format(total, total_format), ha='center', va='bottom', fontsize=8)
    ax.set_xticks(x, labels, fontsize=8)
    ax.margins(y=0.12)
    ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
