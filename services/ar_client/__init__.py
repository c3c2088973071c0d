"""The AR client (paper §III-D, the Visualizer): where is the tablet, and what should it show.

For each camera frame: detect the site's wall tags (detect.py, refine.py), solve the tablet's pose
from all of them at once with ambiguity resolution and tracking (localize.py), project the robots,
their intents and the doors into the image, in X-ray style where walls hide them (project.py,
visibility.py, overlay.py), add the feedback buttons (feedback.py), and publish the result as an
Overlay of 2-D primitives on ``ar/<cid>/overlay`` — optionally also drawn onto the frame (draw.py).
pipeline.py chains these for one frame; service.py runs it on frames from the simulator over Zenoh,
a video, a camera device or a folder of images (sources.py), and keeps a few of the annotated frames
as pictures (snapshots.py).

Also: ``arroch ar localize`` (pose of one image), ``arroch ar render`` (draw a given world state
over an image) and ``arroch tags sheet`` (printable tags at true size, tags_sheet.py).
"""
