"""Response models made from the domain's records (app/server/api/records.py): the model
has the record's fields, no more, no fewer, and refuses a body that lost or gained one."""

from __future__ import annotations

import dataclasses

import pytest
from pydantic import ValidationError

from app.control.timing import TimingStats
from app.programs.check import ProgramReport
from app.server.api.programs import ProgramReportOut
from app.server.api.records import model_of
from app.server.api.responses import LoopStatus, TimingStatsOut

STATS = TimingStats(200.0, 199.5, 5.01, 0.01, 0.2, 0.4, 1, 2000, longest_gap_ms=7.5)


@pytest.mark.parametrize(
    ("record", "model"), [(TimingStats, TimingStatsOut), (ProgramReport, ProgramReportOut)]
)
def test_the_model_has_the_records_fields_in_order_each_required(record, model):
    names = [f.name for f in dataclasses.fields(record)]
    assert list(model.model_fields) == names
    assert all(info.is_required() for info in model.model_fields.values())


def test_a_record_round_trips_and_a_lost_or_an_extra_key_is_refused():
    body = dataclasses.asdict(STATS)
    assert TimingStats(**TimingStatsOut.model_validate(body).model_dump()) == STATS
    lost = {k: v for k, v in body.items() if k != "longest_gap_ms"}
    with pytest.raises(ValidationError, match="longest_gap_ms"):
        TimingStatsOut.model_validate(lost)
    with pytest.raises(ValidationError, match="extra"):  # base=_Out forbids extras
        TimingStatsOut.model_validate({**body, "stray": 1})


def test_a_model_made_from_a_record_can_be_extended():
    """LoopStatus is the record's fields at top level and more (the OpenAPI shape)."""
    extra = set(LoopStatus.model_fields) - set(TimingStatsOut.model_fields)
    assert {"since_start", "last_10s", "health"} <= extra
    assert set(TimingStatsOut.model_fields) <= set(LoopStatus.model_fields)


def test_descriptions_and_types_name_real_fields():
    assert (
        TimingStatsOut.model_fields["longest_gap_ms"].description
        == "the longest time between two ticks' starts [ms]"
    )
    with pytest.raises(KeyError, match="no field 'longest_gap_s'"):
        model_of(TimingStats, "Bad", describe={"longest_gap_s": "a typo"})
    with pytest.raises(TypeError, match="not a dataclass"):
        model_of(dict, "Bad")
