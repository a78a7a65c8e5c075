//! Versioned migrations, one numbered list per backend (`migrations/sqlite/NNNN_*.sql`,
//! `migrations/postgres/NNNN_*.sql`), applied in order at open. The `schema_version`
//! table holds one row per applied migration; each one runs in a transaction with its
//! row, so a failed migration leaves the database at the previous version. A database
//! at a version newer than this server knows is refused rather than misused.
//!
//! SQLite's migration 1 is the schema as it was before this table existed (every
//! statement `IF NOT EXISTS`), so a file made by an earlier version starts at version 1
//! with its data intact. A later change of the schema is a new file in both lists.

use super::{Pool, StoreError};

/// One migration: its number, its name and its SQL (several statements).
struct Migration {
    version: i64,
    name: &'static str,
    sql: &'static str,
}

const SQLITE: &[Migration] = &[
    Migration {
        version: 1,
        name: "initial",
        sql: include_str!("migrations/sqlite/0001_initial.sql"),
    },
    Migration {
        version: 2,
        name: "cluster",
        sql: include_str!("migrations/sqlite/0002_cluster.sql"),
    },
    Migration {
        version: 3,
        name: "audit",
        sql: include_str!("migrations/sqlite/0003_audit.sql"),
    },
];

const POSTGRES: &[Migration] = &[
    Migration {
        version: 1,
        name: "initial",
        sql: include_str!("migrations/postgres/0001_initial.sql"),
    },
    Migration {
        version: 2,
        name: "cluster",
        sql: include_str!("migrations/postgres/0002_cluster.sql"),
    },
    Migration {
        version: 3,
        name: "audit",
        sql: include_str!("migrations/postgres/0003_audit.sql"),
    },
];

const VERSION_TABLE: &str = "CREATE TABLE IF NOT EXISTS schema_version (
    version BIGINT PRIMARY KEY,
    name TEXT NOT NULL,
    applied_at_ms BIGINT NOT NULL
)";

/// Applies the backend's migrations that the database has not seen yet, up to version
/// `until` (`i64::MAX`: all of them; SQLite stops after 1 to add the columns older files
/// lack before the later migrations use them).
pub(super) async fn apply(pool: &Pool, until: i64) -> Result<(), StoreError> {
    let list = match pool {
        Pool::Sqlite(_) => SQLITE,
        Pool::Postgres(_) => POSTGRES,
    };
    let latest = list.last().map_or(0, |m| m.version);
    with_pool!(pool, p => {
        sqlx::query(VERSION_TABLE).execute(p).await?;
        let mut tx = p.begin().await?;
        if matches!(pool, Pool::Postgres(_)) {
            // Two servers starting on one database: the second waits for the first.
            sqlx::query("SELECT pg_advisory_xact_lock(7361029)")
                .execute(&mut *tx)
                .await?;
        }
        let current: i64 = sqlx::query_scalar("SELECT CAST(COALESCE(MAX(version), 0) AS BIGINT) FROM schema_version")
            .fetch_one(&mut *tx)
            .await?;
        if current > latest {
            return Err(StoreError::Corrupt(format!(
                "database schema version {current} is newer than this server's {latest}"
            )));
        }
        for m in list.iter().filter(|m| m.version > current && m.version <= until) {
            sqlx::raw_sql(m.sql).execute(&mut *tx).await?;
            sqlx::query("INSERT INTO schema_version (version, name, applied_at_ms) VALUES ($1, $2, $3)")
                .bind(m.version)
                .bind(m.name)
                .bind(crate::service::now_ms())
                .execute(&mut *tx)
                .await?;
            tracing::info!(version = m.version, name = m.name, "store migration applied");
        }
        tx.commit().await?;
    });
    Ok(())
}
