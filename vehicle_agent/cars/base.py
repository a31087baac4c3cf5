"""Reading the car: one interface every make implements, and the decoded state it produces.

A make module says which DBC messages carry what the agent needs (paper Table 2), how often the
car sends them, where their counters are, and how to turn their signals into a `CarReading`. It
also builds the one kind of frame the agent sends that make (ACC button presses or acceleration
requests). `CarStateReader` (state.py) does the bookkeeping common to all makes.
"""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import ClassVar

from contract.controllers import Actuation
from vehicle_agent.codec import Checksum

Signals = Mapping[str, float]


class CruiseButton(enum.Enum):
    """The ACC buttons the agent reads (driver activity) or presses (plus, minus, gap)."""

    PLUS = "plus"  # resume / accelerate: +1 mph a press, +5 mph held
    MINUS = "minus"  # set / coast: -1 mph a press, -5 mph held
    GAP = "gap"  # cycles the three gap settings
    CANCEL = "cancel"
    MAIN = "main"


# A message the car must keep sending: missing for STALE_PERIODS periods makes the state invalid.
STALE_PERIODS = 10


@dataclass(frozen=True)
class MessageRule:
    """How the agent checks one watched message."""

    period_s: float  # the car's nominal sending period
    counter_signal: str | None = None
    counter_modulo: int = 0


@dataclass(frozen=True, slots=True)
class CarReading:
    """What one make's signals say, before freshness is judged (SI units, mph for settings)."""

    speed_mps: float
    acc_available: bool
    acc_engaged: bool
    acc_speed_setting_mph: float | None
    acc_gap_setting: int | None
    lead_present: bool
    lead_distance_m: float | None = None
    lead_rel_speed_mps: float | None = None
    brake_pressed: bool = False
    gas_pressed: bool = False
    buttons: frozenset[CruiseButton] = field(default_factory=frozenset)
    # the stock ACC holds the car stopped until the driver resumes it (`holds_standstill`)
    standstill_held: bool = False


@dataclass(frozen=True, slots=True)
class CarState:
    """The car at one instant: its reading, and whether every input was fresh and well formed."""

    time_s: float
    valid: bool
    problem: str | None
    reading: CarReading | None
    # when the frame of each watched message the reading was built from was read (the agent's
    # monotonic s): a frame the agent builds from one of them needs that one fresh, which the
    # state's own validity (10 periods) does not tell (`SafetyLayer.check_standstill_release`)
    received_at: Mapping[str, float] = field(default_factory=dict)

    @property
    def speed_mps(self) -> float | None:
        """Ego speed, or None before the first complete reading."""
        return None if self.reading is None else self.reading.speed_mps


class CarInterface(ABC):
    """One make: its DBC, the messages read, and the frames the agent may send."""

    key: ClassVar[str]
    make: ClassVar[str]
    model: ClassVar[str]
    years: ClassVar[tuple[int, ...]]
    dbc_name: ClassVar[str]
    actuation: ClassVar[Actuation]
    messages: ClassVar[dict[str, MessageRule]]
    checksums: ClassVar[dict[str, Checksum]] = {}
    # The one message the agent sends, and how often it sends it while commanding.
    command_message: ClassVar[str]
    command_period_s: ClassVar[float]
    command_counter_signal: ClassVar[str | None] = None
    command_counter_modulo: ClassVar[int] = 0
    # Whether a button frame copies the car's own latest frame of the command message besides
    # its buttons (the Nissan's pedals and brake): a press then needs that frame fresh, or it
    # would tell the car the driver's inputs of a moment ago (`SafetyLayer.check_copy`).
    copies_command_frame: ClassVar[bool] = False
    # Whether the car acts on button frames the agent puts on its bus. The 2023 Nissan Rogue
    # does not (paper, vehicle interface: its protocols "prevented the injection of commands"),
    # so its buttons are pressed electrically, by a GPIO button board (`GpioButtonBoard`), and
    # the agent refuses to drive it without one (`ButtonBoardRequired`).
    accepts_button_frames: ClassVar[bool] = True
    # Whether the car's messages are CAN-FD frames (over 8 bytes), so the bus must be opened
    # for CAN-FD (`vehicle_agent.bus.open_bus`).
    can_fd: ClassVar[bool] = False
    # The message whose latest frame tells whether the stock ACC holds a standstill
    # (`holds_standstill`), for makes whose command frame may release one: a release goes out
    # only while a fresh frame of it shows none held (`SafetyLayer.check_standstill_release`).
    standstill_message: ClassVar[str | None] = None
    # The messages a press is judged from (button makes): whether the ACC is engaged, its set
    # points, the driver's pedals and the standstill hold. The car state stays valid on a frame
    # 10 periods old (1 s of the 2023 Rogue's CRUISE), and a press judged from one that old
    # could land on an ACC the driver has since cancelled (on a car where SET engages it), so a
    # press goes out only while each was read at most `fresh_periods` of its periods ago
    # (`SafetyLayer.check_press`).
    press_inputs: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def interpret(self, signals: Mapping[str, Signals]) -> CarReading:
        """The reading from the latest signals of every watched message."""

    def button_signals(
        self, button: CruiseButton | None, latest: Mapping[str, Signals]
    ) -> dict[str, float]:
        """Signals of the command message pressing `button` (None: all released)."""
        raise NotImplementedError(f"{self.key} is not actuated by ACC buttons")

    def accel_signals(self, accel_mps2: float, *, release_standstill: bool) -> dict[str, float]:
        """Signals of the command message requesting `accel_mps2`, releasing a standstill the
        stock ACC holds (`releases_standstill`) only when `release_standstill`: the agent's
        judgement, from the car's `standstill_message` and its age, not the make's."""
        raise NotImplementedError(f"{self.key} is not actuated by acceleration requests")

    def holds_standstill(self, latest: Mapping[str, Signals]) -> bool:
        """Whether the stock ACC holds the car stopped until the driver resumes it, so that no
        acceleration request moves it (accel makes; none by default)."""
        return False

    def releases_standstill(self, signals: Signals) -> bool:
        """Whether a decoded command frame releases a standstill the stock ACC holds, driving
        off without the driver (accel makes; none by default)."""
        return False

    def commanded_accel(self, signals: Signals) -> float:
        """The acceleration a decoded command frame requests (accel makes)."""
        raise NotImplementedError(f"{self.key} is not actuated by acceleration requests")

    def pressed_buttons(self, signals: Signals) -> frozenset[CruiseButton]:
        """The buttons a decoded command frame presses (button makes)."""
        raise NotImplementedError(f"{self.key} is not actuated by ACC buttons")

    def driver_inputs(self, signals: Signals) -> str | None:
        """The driver's pedal a decoded command frame shows pressed, in words, or None. Only
        makes whose button frames copy the car's own (`copies_command_frame`) carry one. The
        safety layer refuses a press in such a frame: with the driver on a pedal the car is
        the driver's, whatever the agent's override check has yet to see."""
        return None

    def foreign_inputs(self, signals: Signals) -> str | None:
        """What a decoded command frame sets besides what the agent sends on it (button makes:
        a code of no known button, another switch on the same message; accel makes: any signal
        but the request at another value than the frame builder's), or None. The safety layer
        refuses such a frame: read as no press, it would pass as a release, which is always
        allowed, and an acceleration frame carries switches of its own."""
        return None
