#!/usr/bin/env python3
"""List Rust functions longer than a limit (default 150 lines), from `fn` to its closing brace.

Usage: scripts/long-fns.py [--limit N] [--all] [PATH...]   (default PATH: host/src)

A function whose doc comment (the `///` lines just above it, attributes skipped) contains
"long:" is listed as `excused` (the reason is printed) and does not count as a failure unless
--all is given. Exit status 1 when an unexcused function exceeds the limit.
Braces inside strings, chars and comments are skipped; raw strings r#"..."# are handled.
"""
import os
import re
import sys

FN_RE = re.compile(r'^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?(extern\s+"[^"]*"\s+)?fn\s+([A-Za-z_][A-Za-z0-9_]*)')


def strip_code(text):
    """Replace string/char/comment contents with spaces, keeping newlines (so line numbers hold)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith('//', i):
            j = text.find('\n', i)
            j = n if j < 0 else j
            out.append(' ' * (j - i))
            i = j
        elif text.startswith('/*', i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith('/*', j):
                    depth, j = depth + 1, j + 2
                elif text.startswith('*/', j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r'[^\n]', ' ', text[i:j]))
            i = j
        elif c == 'r' and re.match(r'r#*"', text[i:i + 10]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == '_')):
            m = re.match(r'r(#*)"', text[i:])
            end = '"' + m.group(1)
            j = text.find(end, i + len(m.group(0)))
            j = n if j < 0 else j + len(end)
            out.append(re.sub(r'[^\n]', ' ', text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == '\\' else 1
            j += 1
            out.append(re.sub(r'[^\n]', ' ', text[i:j]))
            i = j
        elif c == "'":
            m = re.match(r"'(\\.[^']*|[^\\'])'", text[i:])
            if m:
                out.append(' ' * len(m.group(0)))
                i += len(m.group(0))
            else:  # lifetime
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return ''.join(out)


def doc_reason(lines, idx):
    """The `long:` reason in the doc comment above line idx, or None."""
    j = idx - 1
    doc = []
    while j >= 0:
        s = lines[j].strip()
        if s.startswith('#[') or s.startswith('#!['):
            j -= 1
            continue
        if s.startswith('///'):
            doc.append(s[3:].strip())
            j -= 1
            continue
        break
    text = ' '.join(reversed(doc))
    m = re.search(r'long:\s*(.*)', text)
    return m.group(1) if m else None


def functions(path):
    raw = open(path, encoding='utf-8').read()
    code = strip_code(raw)
    lines = raw.split('\n')
    clines = code.split('\n')
    offsets = [0]
    for l in clines:
        offsets.append(offsets[-1] + len(l) + 1)
    for idx, line in enumerate(clines):
        m = FN_RE.match(line)
        if not m:
            continue
        # find the opening brace (or ';' for a declaration without body)
        pos = offsets[idx] + m.end()
        depth_paren = 0
        while pos < len(code):
            ch = code[pos]
            if ch in '([<':
                depth_paren += 1 if ch != '<' else 0
            if ch in ')]':
                depth_paren -= 1
            if ch == ';' and depth_paren <= 0:
                pos = -1
                break
            if ch == '{' and depth_paren <= 0:
                break
            pos += 1
        if pos < 0 or pos >= len(code):
            continue
        depth = 0
        end = pos
        while end < len(code):
            if code[end] == '{':
                depth += 1
            elif code[end] == '}':
                depth -= 1
                if depth == 0:
                    break
            end += 1
        end_line = code.count('\n', 0, end)
        yield m.group(7), idx + 1, end_line + 1, doc_reason(lines, idx)


def main(argv):
    limit, show_all, paths = 150, False, []
    it = iter(argv)
    for a in it:
        if a == '--limit':
            limit = int(next(it))
        elif a == '--all':
            show_all = True
        else:
            paths.append(a)
    paths = paths or ['host/src']
    files = []
    for p in paths:
        if os.path.isfile(p):
            files.append(p)
        for root, _, names in os.walk(p):
            files += [os.path.join(root, f) for f in names if f.endswith('.rs')]
    failing = 0
    rows = []
    for f in sorted(files):
        for name, start, end, reason in functions(f):
            length = end - start + 1
            if length > limit:
                rows.append((length, f, start, name, reason))
    for length, f, start, name, reason in sorted(rows, reverse=True):
        if reason and not show_all:
            print(f'excused {length:4d}  {f}:{start}  {name}  ({reason})')
        else:
            failing += 1
            print(f'{length:4d}  {f}:{start}  {name}')
    print(f'{failing} function(s) over {limit} lines' + ('' if show_all else ' without a `long:` reason'))
    return 1 if failing else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
