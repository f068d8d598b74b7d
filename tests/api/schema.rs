//! The two migration sets (migrations/sqlite and migrations/postgres) describe the same
//! schema: the same tables with the same columns, types, nullability, keys, foreign keys
//! and indexes, read back from each database's own catalogue after migrating a new one.

use std::collections::BTreeMap;

use aortagen::db::{self, Pool};

use crate::helpers::{create_postgres_database, postgres_server, sqlite_database_url};

/// One table as both catalogues can describe it, in common terms.
#[derive(Debug, Default, PartialEq, Eq)]
struct Table {
    /// column → (type family, not null)
    columns: BTreeMap<String, (&'static str, bool)>,
    /// primary-key columns in key order
    primary_key: Vec<String>,
    /// unique column sets (constraints and unique indexes), each sorted
    unique: Vec<Vec<String>>,
    /// (columns, referenced table, referenced columns, on delete)
    foreign_keys: Vec<(Vec<String>, String, Vec<String>, String)>,
    /// named non-unique indexes: name → columns
    indexes: BTreeMap<String, Vec<String>>,
}

/// The type family of a declared type: what a value of it is, whatever each dialect calls it.
fn family(declared: &str) -> &'static str {
    match declared.to_ascii_lowercase().as_str() {
        "integer" | "bigint" | "int8" => "integer",
        "real" | "double precision" | "float8" => "real",
        "text" => "text",
        "blob" | "bytea" => "blob",
        other => panic!("a column of type {other:?} has no family here"),
    }
}

async fn sqlite_schema(pool: &Pool) -> BTreeMap<String, Table> {
    let names: Vec<String> = sqlx::query_scalar(
        "select name from sqlite_master where type = 'table'
             and name not like 'sqlite_%' and name <> '_sqlx_migrations' order by name",
    )
    .fetch_all(pool)
    .await
    .unwrap();
    let mut schema = BTreeMap::new();
    for name in names {
        let mut table = Table::default();
        let columns: Vec<(String, String, i64, i64)> = sqlx::query_as(sqlx::AssertSqlSafe(
            format!("select name, type, \"notnull\", pk from pragma_table_info('{name}')"),
        ))
        .fetch_all(pool)
        .await
        .unwrap();
        let mut key: Vec<(i64, String)> = Vec::new();
        for (column, declared, not_null, pk) in columns {
            // A primary-key column can never hold null, whatever the catalogue says.
            table
                .columns
                .insert(column.clone(), (family(&declared), not_null == 1 || pk > 0));
            if pk > 0 {
                key.push((pk, column));
            }
        }
        key.sort();
        table.primary_key = key.into_iter().map(|(_, c)| c).collect();
        let foreign: Vec<(i64, String, String, String, String)> =
            sqlx::query_as(sqlx::AssertSqlSafe(format!(
                "select id, \"table\", \"from\", \"to\", on_delete
                 from pragma_foreign_key_list('{name}') order by id, seq"
            )))
            .fetch_all(pool)
            .await
            .unwrap();
        let mut by_id: BTreeMap<i64, (Vec<String>, String, Vec<String>, String)> = BTreeMap::new();
        for (id, target, from, to, on_delete) in foreign {
            let entry = by_id
                .entry(id)
                .or_insert_with(|| (vec![], target, vec![], on_delete.to_ascii_lowercase()));
            entry.0.push(from);
            entry.2.push(to);
        }
        table.foreign_keys = by_id.into_values().collect();
        table.foreign_keys.sort();
        let indexes: Vec<(String, i64, String)> = sqlx::query_as(sqlx::AssertSqlSafe(format!(
            "select name, \"unique\", origin from pragma_index_list('{name}')"
        )))
        .fetch_all(pool)
        .await
        .unwrap();
        for (index, unique, origin) in indexes {
            let mut columns: Vec<String> = sqlx::query_scalar(sqlx::AssertSqlSafe(format!(
                "select name from pragma_index_info('{index}') order by seqno"
            )))
            .fetch_all(pool)
            .await
            .unwrap();
            match (unique, origin.as_str()) {
                (_, "pk") => {}
                (1, _) => {
                    columns.sort();
                    table.unique.push(columns);
                }
                _ => {
                    table.indexes.insert(index, columns);
                }
            }
        }
        table.unique.sort();
        schema.insert(name, table);
    }
    schema
}

async fn postgres_schema(pool: &Pool) -> BTreeMap<String, Table> {
    let names: Vec<String> = sqlx::query_scalar(
        "select table_name::text from information_schema.tables
         where table_schema = 'public' and table_type = 'BASE TABLE'
           and table_name <> '_sqlx_migrations' order by 1",
    )
    .fetch_all(pool)
    .await
    .unwrap();
    let mut schema = BTreeMap::new();
    for name in names {
        let mut table = Table::default();
        let columns: Vec<(String, String, String)> = sqlx::query_as(
            "select column_name::text, data_type::text, is_nullable::text
             from information_schema.columns where table_schema = 'public' and table_name = $1",
        )
        .bind(&name)
        .fetch_all(pool)
        .await
        .unwrap();
        for (column, declared, nullable) in columns {
            table
                .columns
                .insert(column, (family(&declared), nullable == "NO"));
        }
        // Keys, unique constraints and foreign keys from pg_constraint, columns in key order.
        let constraints: Vec<(String, String, String, String)> = sqlx::query_as(
            "select c.contype::text,
                    (select string_agg(a.attname::text, ',' order by k.ord)
                       from unnest(c.conkey) with ordinality k(num, ord)
                       join pg_attribute a on a.attrelid = c.conrelid and a.attnum = k.num),
                    coalesce(c.confrelid::regclass::text, ''),
                    coalesce((select string_agg(a.attname::text, ',' order by k.ord)
                       from unnest(c.confkey) with ordinality k(num, ord)
                       join pg_attribute a on a.attrelid = c.confrelid and a.attnum = k.num), '')
                    || '|' || c.confdeltype::text
             from pg_constraint c where c.conrelid = $1::regclass and c.contype in ('p', 'u', 'f')",
        )
        .bind(&name)
        .fetch_all(pool)
        .await
        .unwrap();
        let split = |s: &str| s.split(',').map(str::to_owned).collect::<Vec<_>>();
        for (kind, columns, target, to_and_action) in constraints {
            match kind.as_str() {
                "p" => table.primary_key = split(&columns),
                "u" => {
                    let mut columns = split(&columns);
                    columns.sort();
                    table.unique.push(columns);
                }
                _ => {
                    let (to, action) = to_and_action.split_once('|').unwrap();
                    let action = match action {
                        "c" => "cascade",
                        "r" => "restrict",
                        "n" => "set null",
                        "d" => "set default",
                        _ => "no action",
                    };
                    table.foreign_keys.push((
                        split(&columns),
                        target,
                        split(to),
                        action.to_owned(),
                    ));
                }
            }
        }
        table.foreign_keys.sort();
        table.unique.sort();
        // Indexes that back no constraint.
        let indexes: Vec<(String, String)> = sqlx::query_as(
            "select i.relname::text,
                    (select string_agg(a.attname::text, ',' order by k.ord)
                       from unnest(x.indkey) with ordinality k(num, ord)
                       join pg_attribute a on a.attrelid = x.indrelid and a.attnum = k.num)
             from pg_index x join pg_class i on i.oid = x.indexrelid
             where x.indrelid = $1::regclass and not x.indisprimary
               and not exists (select 1 from pg_constraint c where c.conindid = x.indexrelid)",
        )
        .bind(&name)
        .fetch_all(pool)
        .await
        .unwrap();
        for (index, columns) in indexes {
            table.indexes.insert(index, split(&columns));
        }
        schema.insert(name, table);
    }
    schema
}

#[tokio::test]
async fn both_migration_sets_describe_the_same_schema() {
    let Some(server) = postgres_server() else {
        eprintln!("AORTAGEN_TEST_POSTGRES_URL is not set: the PostgreSQL schema is not compared");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let sqlite = db::connect(&sqlite_database_url(dir.path()), 2)
        .await
        .unwrap();
    let postgres = db::connect(&create_postgres_database(&server).await, 2)
        .await
        .unwrap();
    let (lite, pg) = (
        sqlite_schema(&sqlite).await,
        postgres_schema(&postgres).await,
    );
    assert!(lite.len() >= 10, "{:?}", lite.keys());
    assert_eq!(
        lite.keys().collect::<Vec<_>>(),
        pg.keys().collect::<Vec<_>>(),
        "the same tables"
    );
    for (name, table) in &lite {
        assert_eq!(table, &pg[name], "table {name}");
    }
    // The same migrations, by version, were applied to both.
    let versions = |pool: &Pool| {
        let pool = pool.clone();
        async move {
            sqlx::query_scalar::<_, i64>("select version from _sqlx_migrations order by version")
                .fetch_all(&pool)
                .await
                .unwrap()
        }
    };
    assert_eq!(versions(&sqlite).await, versions(&postgres).await);
}
