"""The dashboard page; ships in the wheel as the package ``deltadash_static``.

Only here so that an installed copy finds these files with ``importlib.resources`` (see
app/static_files.py); the page itself is HTML, CSS and JavaScript.
"""
