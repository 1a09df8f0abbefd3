"""``puppetcli live``: posing the doll by hand in the browser, recorded as a device session.

``recording`` (the simulation and the session it writes), ``track`` (the device's ticks),
``clock`` (physics locked to the wall), ``protocol`` (page messages), ``scene`` (what the
page draws), ``server`` (aiohttp: page, WebSocket, the real-time loop); the page itself is
``static/`` (three.js shipped in ``static/vendor/three``, MIT licence).
"""
