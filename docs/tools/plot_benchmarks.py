#!/usr/bin/env python3
"""Draws docs/images/paper-vs-softshell.svg from the tables in docs/benchmarks.md.

The points are the paper's Table 1 and softshell's `bench_engine` table as they stand in
docs/benchmarks.md, so after a new benchmark run: paste the table there, rerun this script.
Standard library only (an SVG written by hand), so it runs wherever python3 does.

    python3 docs/tools/plot_benchmarks.py [docs/benchmarks.md] [docs/images/paper-vs-softshell.svg]
"""
import math
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def rows_after(text, heading_pattern, first_column):
    """The rows (lists of cells) of the first table after a line matching heading_pattern whose
    header row starts with first_column."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if re.search(heading_pattern, line))
    for i in range(start, len(lines)):
        if lines[i].startswith('| ' + first_column + ' |'):
            header = [c.strip() for c in lines[i].strip('|').split('|')]
            rows = []
            for line in lines[i + 2:]:
                if not line.startswith('|'):
                    break
                rows.append(dict(zip(header, (c.strip() for c in line.strip('|').split('|')))))
            return rows
    raise SystemExit(f'no table with first column "{first_column}" after "{heading_pattern}"')


def seconds(cell):
    value, unit = cell.split()
    return float(value) * {'s': 1.0, 'ms': 1e-3, 'us': 1e-6}[unit]


def main():
    source = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / 'docs' / 'benchmarks.md'
    target = Path(sys.argv[2]) if len(sys.argv) > 2 else ROOT / 'docs' / 'images' / 'paper-vs-softshell.svg'
    text = source.read_text(encoding='utf-8')
    paper = [(int(r['CVs']), seconds(r['precompute']), seconds(r['solve']), r['model'])
             for r in rows_after(text, r"paper's Table 1", 'model')]
    ours = [(int(r['CVs']), seconds(r['precompute']), seconds(r['warm solve p50']), r['mesh'])
            for r in rows_after(text, r"paper's Table 1", 'mesh')]

    width, height, margin = 900, 380, 60
    panel_w = (width - 3 * margin) / 2
    x_range = (math.log10(5), math.log10(30000))
    y_range = (math.log10(5e-6), math.log10(200))
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'font-family="sans-serif" font-size="12">', f'<rect width="{width}" height="{height}" fill="white"/>']

    def point(panel, cvs, t):
        x0 = margin + panel * (panel_w + margin)
        x = x0 + (math.log10(cvs) - x_range[0]) / (x_range[1] - x_range[0]) * panel_w
        # A time printed as 0 (below the table's resolution: "0 ms") sits at the bottom of the axis.
        y = height - margin - (math.log10(max(t, 10.0 ** y_range[0])) - y_range[0]) / (y_range[1] - y_range[0]) * (height - 2 * margin)
        return x, y

    for panel, title in enumerate(('precomputation (stiffness, once per object)', 'one deformation (warm solve)')):
        x0 = margin + panel * (panel_w + margin)
        out.append(f'<text x="{x0 + panel_w / 2}" y="{margin - 25}" text-anchor="middle" font-size="14">{title}</text>')
        out.append(f'<rect x="{x0}" y="{margin}" width="{panel_w}" height="{height - 2 * margin}" '
                   'fill="none" stroke="#444"/>')
        for e in range(-5, 3):
            _, y = point(panel, 10, 10.0 ** e)
            label = {-5: '10 µs', -4: '0.1 ms', -3: '1 ms', -2: '10 ms', -1: '0.1 s', 0: '1 s', 1: '10 s', 2: '100 s'}[e]
            out.append(f'<line x1="{x0}" x2="{x0 + panel_w}" y1="{y}" y2="{y}" stroke="#ddd"/>')
            out.append(f'<text x="{x0 - 4}" y="{y + 4}" text-anchor="end">{label}</text>')
        for cvs in (10, 100, 1000, 10000):
            x, _ = point(panel, cvs, 1.0)
            out.append(f'<line x1="{x}" x2="{x}" y1="{margin}" y2="{height - margin}" stroke="#ddd"/>')
            out.append(f'<text x="{x}" y="{height - margin + 16}" text-anchor="middle">{cvs}</text>')
        out.append(f'<text x="{x0 + panel_w / 2}" y="{height - margin + 34}" text-anchor="middle">'
                   'control points</text>')
        for cvs, pre, solve, name in paper:
            x, y = point(panel, cvs, pre if panel == 0 else solve)
            out.append(f'<rect x="{x - 5}" y="{y - 5}" width="10" height="10" fill="#c0392b"><title>paper: {name}'
                       '</title></rect>')
        for cvs, pre, solve, name in ours:
            x, y = point(panel, cvs, pre if panel == 0 else solve)
            out.append(f'<circle cx="{x}" cy="{y}" r="4.5" fill="#2e86c1"><title>softshell: {name}</title></circle>')
    lx, ly = margin + 10, height - 12
    out.append(f'<rect x="{lx}" y="{ly - 9}" width="10" height="10" fill="#c0392b"/>'
               f'<text x="{lx + 14}" y="{ly}">the paper (Table 1, i7-3820; the Horse on a GPU)</text>')
    out.append(f'<circle cx="{lx + 360}" cy="{ly - 4}" r="4.5" fill="#2e86c1"/>'
               f'<text x="{lx + 370}" y="{ly}">softshell, every shipped mesh (bench_engine, 2-core EPYC)</text>')
    out.append('</svg>')
    target.write_text('\n'.join(out) + '\n', encoding='utf-8')
    print(f'wrote {target} ({len(paper)} paper rows, {len(ours)} softshell rows)')


if __name__ == '__main__':
    main()
