"""The setup form's questions about a new participant, built from the protocol's covariates
(:mod:`study_app.models.covariate_form`): a category is a list of its levels, a number a field with its range; a
registered participant's stored values are shown instead, read-only."""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtWidgets import QComboBox, QFormLayout, QGroupBox, QLabel, QLineEdit, QVBoxLayout, QWidget

from protocol.study.covariates import Covariate
from study_app.models.covariate_form import CovariateForm

__all__ = ["QtCovariateFields"]


class QtCovariateFields(QGroupBox):
    """The protocol's covariates as form fields (hidden when the protocol declares none).

    Parameters
    ----------
    form
        What is asked and what was typed.
    changed
        Called after each answer (the setup form checks it again).
    """

    def __init__(self, form: CovariateForm, changed: Callable[[], object], parent: QWidget | None = None) -> None:
        super().__init__("About the participant (pseudonymous)", parent)
        self.form = form
        self.on_answer = changed
        outer = QVBoxLayout(self)
        self.layout_ = QFormLayout()
        # the column is narrow: a field keeps the width it needs, a long question goes above its field
        self.layout_.setFieldGrowthPolicy(QFormLayout.FieldGrowthPolicy.AllNonFixedFieldsGrow)
        self.layout_.setRowWrapPolicy(QFormLayout.RowWrapPolicy.WrapLongRows)
        self.note = QLabel()
        self.note.setWordWrap(True)
        self.note.setStyleSheet("color: #555555;")
        outer.addLayout(self.layout_)
        outer.addWidget(self.note)
        self.fields: dict[str, QComboBox | QLineEdit] = {}
        form.changed.connect(self._build)
        self._build()

    def _build(self) -> None:
        """The fields of the questions asked now (or the stored values of a registered participant)."""
        while self.layout_.rowCount():
            self.layout_.removeRow(0)
        self.fields = {}
        form = self.form
        self.setVisible(bool(form.declared))
        if not form.declared:
            return
        if not form.asking:
            stored = form.registered_text()
            self.note.setText(f"Registered with their first session: {stored}" if stored else
                              "Registered before: no covariates were recorded then (they are not asked again)")
            return
        for c in form.declared:
            text = form.texts.get(c.name, "")
            if c.kind == "category":
                box = QComboBox()
                box.addItem("choose…" if c.required else "(not given)", "")
                for level in c.levels:
                    box.addItem(level, level)
                box.setCurrentIndex(max(0, box.findData(text)))
                box.currentIndexChanged.connect(lambda _i, n=c.name, b=box: self._answer(n, str(b.currentData())))
                self.fields[c.name] = box
            else:
                line = QLineEdit(text)
                line.setPlaceholderText(f"{c.lo:g}–{c.hi:g}{' ' + c.unit if c.unit else ''}")  # its range
                line.textChanged.connect(lambda t, n=c.name: self._answer(n, t))
                self.fields[c.name] = line
            self.fields[c.name].setToolTip(c.described())
            self.layout_.addRow(_label(c), self.fields[c.name])
        self.note.setText("Nothing identifying: no names or dates of birth. * required by the protocol.")

    def _answer(self, name: str, text: str) -> None:
        self.form.set_text(name, text)
        self.on_answer()


def _label(c: Covariate) -> str:
    """A field's question, with a number's unit and range: they stay in view once a value is typed (the field's
    placeholder goes), so *12* reads as years, not hours, and *75* is seen to be out of range before the error."""
    mark = " *" if c.required else ""
    if c.kind == "category":
        return c.question + mark
    lo, hi = (f"{int(c.lo)}", f"{int(c.hi)}") if c.kind == "integer" else (f"{c.lo:g}", f"{c.hi:g}")
    return f"{c.question} ({lo}–{hi}{' ' + c.unit if c.unit else ''}){mark}"
