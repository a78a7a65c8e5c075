-- The same tables as SQLite's 0001 plus `severity` (added there later), in Postgres
-- types: BIGINT for every integer (the store reads i64), DOUBLE PRECISION for f64 (binary
-- protocol: bit for bit), identity ids that only grow (one writer task per table).
CREATE TABLE IF NOT EXISTS sessions (
    id TEXT PRIMARY KEY,
    spec TEXT NOT NULL,
    created_at_ms BIGINT NOT NULL
);
CREATE TABLE IF NOT EXISTS alarms (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    session TEXT NOT NULL,
    monitor TEXT NOT NULL,
    test TEXT NOT NULL,
    state TEXT NOT NULL,
    t DOUBLE PRECISION NOT NULL,
    statistic DOUBLE PRECISION NOT NULL,
    threshold DOUBLE PRECISION NOT NULL,
    dof BIGINT NOT NULL,
    delay_s DOUBLE PRECISION NOT NULL,
    raised_at_ms BIGINT NOT NULL,
    cleared_t DOUBLE PRECISION,
    severity TEXT NOT NULL DEFAULT 'alarm'
);
CREATE INDEX IF NOT EXISTS alarms_by_session ON alarms (session, monitor, id);
CREATE INDEX IF NOT EXISTS alarms_by_time ON alarms (raised_at_ms);
CREATE TABLE IF NOT EXISTS models (
    id TEXT PRIMARY KEY,
    name TEXT,
    kind TEXT NOT NULL,
    status TEXT NOT NULL,
    params TEXT NOT NULL,
    n BIGINT NOT NULL,
    dim BIGINT NOT NULL,
    metrics TEXT,
    error TEXT,
    model TEXT,
    created_ms BIGINT NOT NULL,
    finished_ms BIGINT
);
CREATE INDEX IF NOT EXISTS models_by_time ON models (created_ms);
CREATE TABLE IF NOT EXISTS recording_frames (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    session TEXT NOT NULL,
    stream BIGINT NOT NULL,
    first_epoch BIGINT NOT NULL,
    epochs BIGINT NOT NULL,
    recorded_at_ms BIGINT NOT NULL,
    bytes BIGINT NOT NULL,
    frame TEXT NOT NULL,
    events TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS recording_by_session ON recording_frames (session, stream, id);
