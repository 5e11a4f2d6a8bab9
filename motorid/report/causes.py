"""The report's words on what diagnose could not name (issue 15): unexplained structure and empirical terms."""

from __future__ import annotations

from html import escape as esc


def unexplained_words(entries) -> str:
    """One paragraph per unexplained entry of diagnosis.json: its description, and the proposed
    empirical term labelled as such (never as a named mechanism); stand-ins refused are said too."""
    if not isinstance(entries, list):
        return ""
    out = []
    for u in entries:
        if not isinstance(u, dict) or "description" not in u:
            continue
        text = f"<p class=\"unexplained\"><b>Unexplained</b>: {esc(str(u['description']))}"
        term = u.get("empirical_term")
        if isinstance(term, dict) and term.get("formula"):
            gains = term.get("region_gain") or {}
            where = "; ".join(f"{esc(k)}: {100 * v:.0f} %" for k, v in gains.items())
            text += (f"<br>Empirical term (not a named mechanism, a shape to look into): "
                     f"<code>{esc(term['formula'])}</code> ({esc(str(term.get('size_words', '')))}); it removes "
                     f"{100 * term.get('held_out_gain', 0.0):.0f} % of the residual χ² on runs held out of its fit"
                     + (f"; where it was not fitted — {where}" if where else "") + ".")
        out.append(text + "</p>")
    return "".join(out)


def refused_words(refused) -> str:
    """Candidates that fitted but did not predict the regions they were not fitted on."""
    if not isinstance(refused, list) or not refused:
        return ""
    items = []
    for r in refused:
        if not isinstance(r, dict):
            continue
        failed = [s["split"] for s in (r.get("extrapolation") or {}).get("splits", []) if s.get("failed")]
        why = str(r.get("why") or "fails where it was not fitted")
        where = f" ({'; '.join(failed)})" if failed else ""
        items.append(f"<li><code>{esc(str(r.get('id')))}</code> fitted the logs but was not kept as a name: "
                     f"{esc(why + where)}</li>")
    return "<p>Stand-ins refused:</p><ul>" + "".join(items) + "</ul>" if items else ""
