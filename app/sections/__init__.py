"""Section classes of a line (A … E per section from the speed-conditioned stiffness index), the
length per class now and a year before (:mod:`~app.sections.service`)."""
