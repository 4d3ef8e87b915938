"""The README stays short, and every link between the documents lands on a file and heading."""

import glob
import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MAX_README_LINES = 299   # "under 300": the rest belongs in docs/
LINK = re.compile(r'\]\(([^)\s]+)\)')


def documents():
    return ['README.md'] + sorted(os.path.relpath(p, ROOT)
                                  for p in glob.glob(os.path.join(ROOT, 'docs', '*.md')))


def slugs(path):
    """Return the anchors GitHub makes of a Markdown file's headings."""
    found = set()
    with open(os.path.join(ROOT, path), encoding='utf-8') as stream:
        fenced = False
        for line in stream:
            if line.startswith('```'):
                fenced = not fenced
            elif not fenced and line.startswith('#'):
                title = line.lstrip('#').strip().lower()
                slug = re.sub(r'[^\w\- ]', '', title).replace(' ', '-')
                found.add(slug)
    return found


def test_the_readme_is_under_300_lines():
    with open(os.path.join(ROOT, 'README.md'), encoding='utf-8') as stream:
        assert len(stream.read().splitlines()) <= MAX_README_LINES


def test_every_relative_link_lands_on_a_file_and_a_heading():
    broken = []
    for document in documents():
        text = open(os.path.join(ROOT, document), encoding='utf-8').read()
        for target in LINK.findall(text):
            if target.startswith(('http://', 'https://', 'mailto:')):
                continue
            path, _, anchor = target.partition('#')
            where = os.path.normpath(os.path.join(os.path.dirname(document), path)) \
                if path else document
            if not os.path.exists(os.path.join(ROOT, where)):
                broken.append(f'{document}: {target} (no file)')
            elif anchor and where.endswith('.md') and anchor not in slugs(where):
                broken.append(f'{document}: {target} (no heading)')
    assert broken == []
