"""Reports from results: a ``Report`` of blocks rendered to Markdown and self-contained HTML
(``document``), a section per kind of result (``sections``), the figures of the command line
(``figures``), how a number reads (``numbers``) and the study ``negstiff report`` runs on a lab's own
record (``record``).
"""
