"""A blind rating study of two policies' naturalness that raters run in a browser.

Reproduces the user study of Christen et al. (ICRA 2019), Table I: raters watch pairs
of videos of the same task from identical starts, one policy trained with the
imitation reward and one without, in a hidden left/right order, and answer on a
five-point scale; the report maps each answer to -2..+2 (positive: the imitation
policy looks more natural) and tests the mean per task against 0.

    python -m mjx_hands.study make ...                  # render the videos (make.py)
    python -m mjx_hands.study serve STUDY_DIR [--port 8000]
    python -m mjx_hands.study report STUDY_DIR [--out DIR]

Modules: ``layout`` (the study folder: study.json, key.json, videos/), ``store``
(answers.sqlite), ``server`` (the page and its JSON API), ``report`` (Table I).
"""
