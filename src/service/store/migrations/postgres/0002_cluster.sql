-- Scale-out (docs/deployment.md): one owner per session through a lease with a fencing
-- epoch, the owner's checkpoints, and a key that makes an alarm re-raised after a
-- failover (the same stream, epoch, monitor, test, state and severity) one log entry.
CREATE TABLE leases (
    session TEXT PRIMARY KEY,
    owner TEXT NOT NULL,
    epoch BIGINT NOT NULL,
    expires_ms BIGINT NOT NULL,
    address TEXT NOT NULL DEFAULT ''
);
CREATE INDEX leases_by_owner ON leases (owner);
CREATE TABLE checkpoints (
    session TEXT PRIMARY KEY,
    lease_epoch BIGINT NOT NULL,
    version BIGINT NOT NULL,
    epochs BIGINT NOT NULL,
    t DOUBLE PRECISION,
    taken_at_ms BIGINT NOT NULL,
    state BYTEA NOT NULL
);
ALTER TABLE alarms ADD COLUMN stream BIGINT NOT NULL DEFAULT 0;
ALTER TABLE alarms ADD COLUMN epoch_index BIGINT NOT NULL DEFAULT 0;
CREATE UNIQUE INDEX alarms_once ON alarms (session, stream, epoch_index, monitor, test, state, severity) WHERE stream > 0;
