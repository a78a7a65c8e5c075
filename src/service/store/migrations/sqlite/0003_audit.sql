-- The audit log (docs/architecture.md §A4): one row per change a caller made through the
-- API, and the acknowledgement of an alarm-log entry by a person.
CREATE TABLE audit_log (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL,
    actor TEXT NOT NULL,
    client TEXT,
    forwarded_for TEXT,
    method TEXT NOT NULL,
    route TEXT NOT NULL,
    path TEXT NOT NULL,
    session TEXT,
    reason TEXT,
    previous_value TEXT NOT NULL,
    new_value TEXT NOT NULL
);
CREATE INDEX audit_by_session ON audit_log (session, id);
CREATE INDEX audit_by_time ON audit_log (at_ms);
ALTER TABLE alarms ADD COLUMN acked_by TEXT;
ALTER TABLE alarms ADD COLUMN acked_at_ms INTEGER;
ALTER TABLE alarms ADD COLUMN ack_comment TEXT;
