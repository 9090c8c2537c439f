"""reports/templates/lists.html: the findings and sentences lists every report page draws from one macro."""
from markupsafe import Markup

from reports.html import environment


def _render(source: str, **ctx) -> str:
    env = environment()
    return env.from_string('{% from "lists.html" import findings, sentences %}' + source).render(**ctx)


def test_a_finding_shows_its_reproducer_and_what_judged_it_and_a_page_s_finding_without_a_judge_renders():
    items = [{"cls": "bad", "text": "a <b> contradicts", "repro": "repro/x.py", "judged": "order 1 vs 2"},
             {"cls": "info", "text": "as expected", "repro": ""}]     # a scenario page's: no "judged" key
    html = _render("{{ findings(items) }}", items=items)
    assert html.count("<li ") == 2 and 'class="findings"' in html
    assert '<a class="small" href="repro/x.py">reproducer</a>' in html
    assert "Judged: order 1 vs 2" in html and html.count("Judged") == 1
    assert "a &lt;b&gt; contradicts" in html          # escaped, as the pages were


def test_sentences_are_info_items_escaped():
    html = _render("{{ sentences(s) }}", s=["x < y", Markup("<i>kept</i>")])
    assert html.count('<li class="info">') == 2 and "x &lt; y" in html and "<i>kept</i>" in html
