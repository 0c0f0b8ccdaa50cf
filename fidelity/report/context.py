"""The context of use and its credibility assessment
(:class:`fidelity.pipeline.context.ContextAssessment`) as a section of an HTML report."""

from __future__ import annotations

from typing import TYPE_CHECKING

from fidelity.report.document import Section, section, table

if TYPE_CHECKING:  # a report without a context of use loads none of its machinery
    from fidelity.pipeline.context import ContextAssessment


def context_section(a: ContextAssessment) -> Section:
    """The context of use and its credibility assessment, for an HTML report."""
    c = a.context
    facts = table(("factor", "level", "reason"),
                  [[f.name, str(f.level), f.reason] for f in a.factors]
                  + [["credibility (lowest factor)", str(a.credibility_level),
                      f"required by model risk level {a.required_level} (influence "
                      f"{c.model_influence}, consequence {c.decision_consequence}): "
                      + ("sufficient" if a.sufficient else "insufficient")]],
                  caption=f"Context of use {c.name} ({c.path})")
    outside = (table(("outside the validity domain",), [[o] for o in a.outside])
               if a.outside else None)
    acc = (table(("subject", "criterion", "limit", "value", "met"),
                 [[x.subject, x.criterion, f"{x.limit:g}",
                   "-" if x.value is None else f"{x.value:.2f}", "yes" if x.passed else "no"]
                  for x in a.acceptance]) if a.acceptance else None)
    return section("Context of use", facts, outside, acc)


__all__ = ["context_section"]
