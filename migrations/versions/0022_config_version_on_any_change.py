"""Any change of what a car's config says bumps its config_version, SQL included.

Revision ID: 0022
Revises: 0021
Create Date: 2026-12-06 10:00:00+00:00

`dim_vehicle.config_version` was bumped by the code that changes a car: the assignment API, the
maintenance API, the dashboard's forms, a roster import. Setting `is_active` has no command or
page: operators pull a car with SQL (`smoothfleet db psql`), which left the version as it was.
The car learns of a new config from the version the server names in every plan answer
(`X-Config-Version`, docs/interfaces.md) and fetches the config when it differs: without a new
version a car pulled this way went on being commanded until its next full config refresh (60 s),
and the fleet page's echoed version said nothing had changed.

A trigger bumps the version when an update changes any column the config is made of and leaves
the version itself as it was; an update that sets the version (every writer in the code) keeps
the one it set, so a change is never counted twice and `fact_vehicle_change` stays keyed by the
version the writer recorded.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0022"
down_revision: str | None = "0021"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TRIGGER = """
-- The columns of dim_vehicle the vehicle config is made of (app/vehicles/reports.py).
CREATE FUNCTION bump_vehicle_config_version() RETURNS trigger
LANGUAGE plpgsql AS $$
BEGIN
    IF NEW.config_version IS NOT DISTINCT FROM OLD.config_version THEN
        NEW.config_version := OLD.config_version + 1;
    END IF;
    RETURN NEW;
END
$$;
COMMENT ON FUNCTION bump_vehicle_config_version() IS
    'A change of a vehicle''s config that set no new config_version gets one (trigger function).';

CREATE TRIGGER vehicle_config_changed
    BEFORE UPDATE ON dim_vehicle
    FOR EACH ROW
    WHEN ((OLD.make, OLD.model, OLD.year, OLD.actuation, OLD.corridor_id, OLD.route,
           OLD.assigned_lane, OLD.controller_name, OLD.controller_params, OLD.is_active,
           OLD.is_in_maintenance)
          IS DISTINCT FROM
          (NEW.make, NEW.model, NEW.year, NEW.actuation, NEW.corridor_id, NEW.route,
           NEW.assigned_lane, NEW.controller_name, NEW.controller_params, NEW.is_active,
           NEW.is_in_maintenance))
    EXECUTE FUNCTION bump_vehicle_config_version();
"""

DROP_TRIGGER = """
DROP TRIGGER vehicle_config_changed ON dim_vehicle;
DROP FUNCTION bump_vehicle_config_version();
"""


def upgrade() -> None:
    op.execute(TRIGGER)


def downgrade() -> None:
    op.execute(DROP_TRIGGER)
