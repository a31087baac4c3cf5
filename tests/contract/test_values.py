"""Helpers of the contract's values."""

from __future__ import annotations

import pytest
from pydantic import BaseModel, Field, ValidationError, field_validator

from contract.values import first_problem


def test_the_first_problem_is_told_in_the_failing_checks_own_words() -> None:
    """A validator's ValueError is read from the exception (pydantic words it "Value error,
    ..."), a constraint's in pydantic's words, each with where it was found."""

    class Lane(BaseModel):
        lane: int = Field(ge=1)
        name: str

        @field_validator("name")
        @classmethod
        def _named(cls, value: str) -> str:
            if not value.strip():
                raise ValueError("a name needs a character that is not white space")
            return value

    with pytest.raises(ValidationError) as blank:
        Lane(lane=1, name=" ")
    problem = first_problem(blank.value)
    assert (problem.location, problem.message) == (
        ("name",),
        "a name needs a character that is not white space",
    )
    with pytest.raises(ValidationError) as low:
        Lane(lane=0, name="a")
    assert str(first_problem(low.value)) == "lane: Input should be greater than or equal to 1"
