"""Where windows open: their last place if it is still on a screen, else a size that fits, on the right screen.

The experimenter's window must fit a 1366×768 laptop; the participant screen
belongs on the second monitor when there is one; every window is saved (and
restored) in the settings by name.
"""

from __future__ import annotations

from PySide6.QtCore import QByteArray, QRect, QSettings, QSize, Qt
from PySide6.QtGui import QGuiApplication, QScreen
from PySide6.QtWidgets import QWidget

__all__ = ["BESIDE_MIN", "centre_on_a_screen", "fit_size", "keep_above", "leave_room_beside", "onto_a_screen",
           "other_screen", "over_the_older_plots", "place", "place_beside", "place_over", "restore", "save",
           "side_by_side"]

#: A restored window must show at least this much of itself on some screen, px (else it is placed afresh).
_MIN_VISIBLE = 120


def _screen_of(widget: QWidget | None) -> QScreen:
    s = widget.screen() if widget is not None else None
    return s if s is not None else QGuiApplication.primaryScreen()


def other_screen(widget: QWidget | None) -> QScreen | None:
    """A screen other than the one ``widget`` is on (the participant's monitor), or None with one screen."""
    mine = _screen_of(widget)
    others = [s for s in QGuiApplication.screens() if s is not mine]
    return others[0] if others else None


def fit_size(preferred: QSize, screen: QScreen, margin: int = 40) -> QSize:
    """``preferred``, shrunk to fit the screen's available area less a margin."""
    avail = screen.availableGeometry()
    return QSize(min(preferred.width(), avail.width() - margin), min(preferred.height(), avail.height() - margin))


#: The window manager's title bar and borders before a window is first shown (then measured), px.
FRAME_ALLOWANCE = QSize(8, 34)


def frame_extra(window: QWidget) -> QSize:
    """How much larger the frame (title bar, borders) is than the window's contents: measured once shown."""
    if window.isVisible():
        f, g = window.frameGeometry(), window.geometry()
        if f.height() > g.height() or f.width() > g.width():
            return QSize(f.width() - g.width(), f.height() - g.height())
    return FRAME_ALLOWANCE


def place(window: QWidget, preferred: QSize, screen: QScreen) -> None:
    """Size ``window`` to fit ``screen`` and centre it there -- its frame, title bar included, not just its contents
    (``move`` places the frame, ``resize`` sizes the contents: a 728-px window centred by its contents on a
    768-px screen put the bottom of a 753-px frame 5 px below the screen)."""
    avail = screen.availableGeometry()
    extra = frame_extra(window)
    size = fit_size(preferred.expandedTo(QSize(1, 1)), screen)
    size = size.boundedTo(QSize(avail.width() - extra.width(), avail.height() - extra.height()))
    size = size.expandedTo(window.minimumSizeHint().boundedTo(avail.size() - extra))
    window.resize(size)
    x = avail.x() + max(0, (avail.width() - size.width() - extra.width()) // 2)
    y = avail.y() + max(0, (avail.height() - size.height() - extra.height()) // 2)
    window.move(x, y)


#: The participant screen beside the experimenter's window on one monitor: at least this size, px (contents).  On a
#: 1366-px laptop the experimenter's window is narrowed to leave it this much room, never covered by it.
BESIDE_MIN = QSize(360, 240)


def side_by_side(avail: QRect, main: QRect, main_min_width: int, preferred: QSize,
                 extra: QSize) -> tuple[QRect, QRect] | None:
    """The experimenter window's frame and the participant screen's frame side by side on one monitor, neither
    over the other: (main, participant), or None when the screen is too narrow for both.

    The participant screen goes on the wider side of ``main`` (the experimenter window's frame) when that side has
    room for :data:`BESIDE_MIN`; else the main window moves to the screen's left edge and narrows (to
    ``main_min_width`` at the least, its frame) to leave that room on its right.  The participant screen is at
    most ``preferred`` (contents), as tall as its width keeps ``preferred``'s shape, top-aligned with the main
    window.  ``extra`` is a frame's size beyond its contents.
    """
    min_w = BESIDE_MIN.width() + extra.width()
    want_w = preferred.width() + extra.width()
    right, left = avail.right() - main.right(), main.left() - avail.left()
    if max(right, left) < min_w:
        width = min(main.width(), avail.width() - min_w)
        if width < main_min_width:
            return None
        main = QRect(avail.left(), main.top(), width, main.height())
        right, left = avail.right() - main.right(), 0
    width = min(want_w, max(right, left))
    content_w = width - extra.width()
    height = min(avail.height(), max(BESIDE_MIN.height(), content_w * preferred.height() // max(1, preferred.width()))
                 + extra.height())
    top = min(max(main.top(), avail.top()), avail.bottom() + 1 - height)
    x = main.right() + 1 if right >= left else main.left() - width
    return main, QRect(x, top, width, height)


def over_the_older_plots(avail: QRect, keep_clear: QRect, preferred: QSize, extra: QSize) -> QRect:
    """Where the participant screen goes on a screen too narrow for it beside the experimenter's window: at the
    bottom, just right of ``keep_clear`` (the controls), over the older seconds of the plots and the trial table's
    first columns -- never over the controls, the plots' newest seconds (their right edge) or the table's outcome
    columns (its right half), so at most half of what is right of the controls."""
    x0 = max(avail.left(), keep_clear.right() + 9)  # a gap, so the controls' edge stays visible
    width = min(preferred.width() + extra.width(), max(1, (avail.right() + 1 - x0) // 2))
    height = min(preferred.height() + extra.height(), avail.height() // 2)
    return QRect(x0, avail.bottom() + 1 - height, width, height)


def place_beside(window: QWidget, main: QWidget, keep_clear: QWidget, preferred: QSize) -> None:
    """Open ``window`` beside ``main`` on ``main``'s screen (:func:`side_by_side`; ``main`` moved and narrowed to
    leave the room if it must be), else over ``main``'s older plots, clear of ``keep_clear``
    (:func:`over_the_older_plots`)."""
    avail = _screen_of(main).availableGeometry()
    extra, main_extra = frame_extra(window), frame_extra(main)
    layout = side_by_side(avail, main.frameGeometry(), main.minimumWidth() + main_extra.width(), preferred, extra)
    if layout is None:
        clear = QRect(keep_clear.mapToGlobal(keep_clear.rect().topLeft()), keep_clear.size())
        frame = over_the_older_plots(avail, clear, preferred, extra)
    else:
        main_frame, frame = layout
        if main_frame != main.frameGeometry():
            if main.isMaximized() or main.isFullScreen():
                main.showNormal()
            main.resize(main_frame.width() - main_extra.width(), main_frame.height() - main_extra.height())
            main.move(main_frame.topLeft())
    window.resize(frame.width() - extra.width(), frame.height() - extra.height())
    window.move(frame.topLeft())


def leave_room_beside(main: QWidget, preferred: QSize) -> None:
    """On a machine with one monitor, move (and narrow, if it must) the experimenter's window so the participant
    screen fits beside it (:func:`side_by_side`): at 1920 px it sits at the left edge instead of the centre."""
    if other_screen(main) is not None:
        return
    avail = _screen_of(main).availableGeometry()
    extra = frame_extra(main)
    layout = side_by_side(avail, main.frameGeometry(), main.minimumWidth() + extra.width(), preferred, FRAME_ALLOWANCE)
    if layout is not None and layout[0] != main.frameGeometry():
        main.resize(layout[0].width() - extra.width(), layout[0].height() - extra.height())
        main.move(layout[0].topLeft())


def place_over(window: QWidget, preferred: QSize, main: QWidget) -> None:
    """Size ``window`` to fit ``main``'s screen and centre it over ``main`` (kept on the screen): a window of the
    experimenter's (the rig view, the calibration window) opens over the experimenter's window, not over a
    participant screen beside it."""
    place(window, preferred, _screen_of(main))
    avail, frame = _screen_of(main).availableGeometry(), window.frameGeometry()
    centre = main.frameGeometry().center()
    x = min(max(centre.x() - frame.width() // 2, avail.left()), avail.right() + 1 - frame.width())
    y = min(max(centre.y() - frame.height() // 2, avail.top()), avail.bottom() + 1 - frame.height())
    window.move(x, y)


def onto_a_screen(window: QWidget) -> None:
    """Bring ``window`` wholly onto the screen that shows most of it (or the nearest one, if it is off every
    monitor: a monitor unplugged, a saved place under a panel or 20 px below the edge), shrunk if it is larger."""
    frame = window.frameGeometry()
    screens = QGuiApplication.screens()
    if not screens or window.isFullScreen() or window.isMaximized():
        return

    def score(s: QScreen) -> tuple[int, int]:
        common = frame.intersected(s.availableGeometry())
        gap = (s.availableGeometry().center() - frame.center()).manhattanLength()
        return (common.width() * common.height() if common.isValid() else 0, -gap)

    avail = max(screens, key=score).availableGeometry()
    extra = frame_extra(window)
    w, h = min(frame.width(), avail.width()), min(frame.height(), avail.height())
    x = min(max(frame.left(), avail.left()), avail.right() + 1 - w)
    y = min(max(frame.top(), avail.top()), avail.bottom() + 1 - h)
    if (x, y, w, h) != (frame.left(), frame.top(), frame.width(), frame.height()):
        window.resize(w - extra.width(), h - extra.height())
        window.move(x, y)


def centre_on_a_screen(window: QWidget) -> bool:
    """Whether the middle of ``window`` (where the participant screen's cue word is) is on a monitor."""
    centre = window.frameGeometry().center()
    return any(s.geometry().contains(centre) for s in QGuiApplication.screens())


def keep_above(window: QWidget, main: QWidget) -> None:
    """On ``main``'s monitor, make ``window`` a utility window of ``main`` (X11 and the window managers keep such a
    window above its transient parent), so it stays in view beside ``main``'s controls when the experimenter
    clicks in ``main``; on a monitor of its own it is an ordinary window."""
    shared = other_screen(main) is None or window.screen() is main.screen()
    wanted = Qt.WindowType.Tool if shared else Qt.WindowType.Window
    if window.windowType() != wanted:
        geometry = window.saveGeometry()
        window.setWindowFlags(wanted)  # (this hides it)
        window.restoreGeometry(geometry)
    window.winId()
    handle = window.windowHandle()
    if handle is not None:
        handle.setTransientParent(main.windowHandle() if shared else None)  # type: ignore[arg-type]  # None: none


def _on_a_screen(rect: QRect) -> bool:
    for s in QGuiApplication.screens():
        common = rect.intersected(s.availableGeometry())
        if common.width() >= _MIN_VISIBLE and common.height() >= _MIN_VISIBLE:
            # the title bar (top edge) must be reachable to move the window
            return s.availableGeometry().contains(rect.center()) or common.top() == rect.top()
    return False


def restore(window: QWidget, settings: QSettings, key: str) -> bool:
    """Restore ``window``'s saved geometry if there is one and it is on a screen now; True if restored."""
    geom = settings.value(f"window/{key}")
    if not isinstance(geom, (QByteArray, bytes)) or not window.restoreGeometry(geom):
        return False
    return _on_a_screen(window.frameGeometry())


def save(window: QWidget, settings: QSettings, key: str) -> None:
    """Remember ``window``'s geometry (position, size, maximised) under ``key``."""
    settings.setValue(f"window/{key}", window.saveGeometry())
