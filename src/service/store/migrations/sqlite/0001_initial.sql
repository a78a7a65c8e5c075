-- The schema as it was before versioned migrations existed: every statement is
-- IF NOT EXISTS, so a database made by an earlier version passes through it unchanged
-- (its alarms table may still lack `severity`: Store::open adds it, ADDED_COLUMNS).
CREATE TABLE IF NOT EXISTS sessions (
    id TEXT PRIMARY KEY,
    spec TEXT NOT NULL,
    created_at_ms INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS alarms (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    session TEXT NOT NULL,
    monitor TEXT NOT NULL,
    test TEXT NOT NULL,
    state TEXT NOT NULL,
    t REAL NOT NULL,
    statistic REAL NOT NULL,
    threshold REAL NOT NULL,
    dof INTEGER NOT NULL,
    delay_s REAL NOT NULL,
    raised_at_ms INTEGER NOT NULL,
    cleared_t REAL
);
CREATE INDEX IF NOT EXISTS alarms_by_session ON alarms (session, monitor, id);
CREATE INDEX IF NOT EXISTS alarms_by_time ON alarms (raised_at_ms);
CREATE TABLE IF NOT EXISTS models (
    id TEXT PRIMARY KEY,
    name TEXT,
    kind TEXT NOT NULL,
    status TEXT NOT NULL,
    params TEXT NOT NULL,
    n INTEGER NOT NULL,
    dim INTEGER NOT NULL,
    metrics TEXT,
    error TEXT,
    model TEXT,
    created_ms INTEGER NOT NULL,
    finished_ms INTEGER
);
CREATE INDEX IF NOT EXISTS models_by_time ON models (created_ms);
CREATE TABLE IF NOT EXISTS recording_frames (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    session TEXT NOT NULL,
    stream INTEGER NOT NULL,
    first_epoch INTEGER NOT NULL,
    epochs INTEGER NOT NULL,
    recorded_at_ms INTEGER NOT NULL,
    bytes INTEGER NOT NULL,
    frame TEXT NOT NULL,
    events TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS recording_by_session ON recording_frames (session, stream, id);
