"""Where windows open: their last place if it is still on a screen, else a size that fits, on the right screen.

The experimenter's window must fit a 1366×768 laptop; the participant screen
belongs on the second monitor when there is one; every window is saved (and
restored) in the settings by name.
"""

from __future__ import annotations

from PySide6.QtCore import QByteArray, QRect, QSettings, QSize, Qt
from PySide6.QtGui import QGuiApplication, QScreen
from PySide6.QtWidgets import QWidget

__all__ = ["beside", "fit_size", "keep_above", "other_screen", "place", "place_beside", "restore", "save"]

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


#: Smallest window placed beside another, px (contents): smaller than this, it goes over the other's right part.
BESIDE_MIN = QSize(480, 320)


def beside(avail: QRect, main: QRect, keep_clear: QRect, preferred: QSize, extra: QSize) -> QRect:
    """Where a second window opens on the experimenter's only screen (its frame, title bar included).

    Beside ``main`` (the experimenter window's frame) where the screen has room for at least
    :data:`BESIDE_MIN` -- the wider side; else in the screen's bottom-right corner, over the main window's
    right part (its plots and tables) but clear of ``keep_clear`` (its controls: the setup form and the
    buttons), at most ``preferred`` in size.  ``extra`` is the frame's size beyond the contents.
    """
    want = QSize(preferred.width() + extra.width(), preferred.height() + extra.height())
    right = avail.right() - main.right()
    left = main.left() - avail.left()
    min_w = BESIDE_MIN.width() + extra.width()
    height = min(want.height(), avail.height())
    if max(right, left) >= min_w:
        width = min(want.width(), max(right, left))
        x = main.right() + 1 if right >= left else main.left() - width
        return QRect(x, avail.top(), width, height)
    x0 = max(avail.left(), keep_clear.right() + 9)  # a gap, so the controls' edge stays visible
    # never over the controls, even on a screen too small for BESIDE_MIN (then it is as wide as there is room)
    width = min(want.width(), avail.right() + 1 - x0)
    height = min(height, max(BESIDE_MIN.height() + extra.height(), avail.height() * 2 // 3))
    return QRect(avail.right() + 1 - width, avail.bottom() + 1 - height, width, height)


def place_beside(window: QWidget, main: QWidget, keep_clear: QWidget, preferred: QSize) -> None:
    """Open ``window`` beside ``main`` on ``main``'s screen, clear of ``keep_clear`` (see :func:`beside`)."""
    screen = _screen_of(main)
    extra = frame_extra(window)
    clear = QRect(keep_clear.mapToGlobal(keep_clear.rect().topLeft()), keep_clear.size())
    frame = beside(screen.availableGeometry(), main.frameGeometry(), clear, preferred, extra)
    window.resize(frame.width() - extra.width(), frame.height() - extra.height())
    window.move(frame.topLeft())


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
