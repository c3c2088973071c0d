"""The tablet client: the AR view and the feedback buttons in a tablet's browser (``arroch tablet``).

A person opens a page on a tablet (no app to install), points the rear camera at the building and
sees the robots, their plans and the doors over the live camera image, and taps feedback.

- :mod:`.server` serves the page (``static/``) over HTTPS and one WebSocket per page;
- :mod:`.session` runs one page's WebSocket: camera frames in, that frame's Overlay out, feedback
  in, acks out, the world (robots, intents, doors) for the map view;
- :mod:`.bridge` is the server's Zenoh side (a :class:`runtime.service.Service`): the world state,
  the live constraints, feedback to the restrictor, the sim's camera stream for viewer mode;
- :mod:`.wire` is the page protocol (binary frames, JSON messages) and its limits;
- :mod:`.security` the per-run access token, the Origin check, the certificate, rate limits;
- :mod:`.intrinsics` the camera model of a browser stream (calibration file or default field of view);
- :mod:`.calibrate` ``arroch ar calibrate`` (chessboard or ChArUco images → intrinsics file);
- :mod:`.announce` the URLs to open, printed and as a QR code in the terminal;
- :mod:`.fakecam` a camera video file for Chromium's fake capture device, for the end-to-end tests
  and the latency benchmark (which drive Chromium with Playwright: ``tests/tablet/browser.py``).

Study mode (``arroch tablet --study-trial FILE``, the page a study participant uses during a trial):

- :mod:`.study_trial` the trial file (participant, condition, puzzle, questionnaires, consent);
- :mod:`.study` the trial on the server: what she may do now, and the record of what she did;
- :mod:`.study_wire` the study page's requests; :mod:`.study_store` its progress across restarts;
- :mod:`.puzzle` the Jigsaw puzzle's arrangement and moves; :mod:`.puzzle_picture` its picture;
- :mod:`.questionnaire` the paper's Q1-Q5 and raw NASA-TLX, and the check of the answers.
"""
