"""The web page of the service and of ``onboard shore --web``: a live map of the track,
the current with its uncertainty, speed and heading with their sigma, integrity flags and
health (docs/service.md, "Web page").

* :mod:`.view`: the page's model (:class:`~.view.LiveView`), fed with the in-process
  estimate and health records (the service) or with Zenoh samples (the shore);
* :mod:`.http`: a small asyncio HTTP/1.1 server (GET and POST, no keep-alive);
* :mod:`.app`: the routes: the page, BlueOS's discovery (``/register_service``, the
  Cockpit widget description) and the JSON API the page polls;
* :mod:`.config_edit`: the configuration shown and edited from the page;
* ``static/``: the page itself (HTML and hand-written canvas JS, no external dependency).
"""
