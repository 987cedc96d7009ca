"""The networks: E, G, D, D3 and the pose and light heads (:mod:`.nets`), the colour G offsets from, read
from the input photo (:mod:`.photo_colours`), and the ``model:`` section that sizes them (:mod:`.settings`).
Above the renderer (G's colour is read along the input camera's rays), below the config. Imports nothing.
"""
