//! The run's private folder with everything a run puts in it, ports included: private to its
//! owner, left empty at the end, and never reached through a link or a folder another user made.
//! Here, beside the ports, since storage sits below the transport.

use std::os::unix::fs::{MetadataExt, PermissionsExt};

use crate::runtime::storage::run_storage::*;
use crate::runtime::storage::snapshot::Snapshot;
use crate::runtime::transport::ipc::*;

fn unique_id(name: &str) -> String {
    format!("test{}{name}", std::process::id())
}

/// As root, makes `path` another user's (nobody's), as an attacker's file would be; returns
/// false where this user cannot.
fn give_away(path: &std::path::Path) -> bool {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return false;
    }
    std::os::unix::fs::lchown(path, Some(65534), Some(65534)).unwrap();
    true
}

#[test]
fn a_run_keeps_everything_private_and_leaves_nothing() {
    let id = unique_id("private");
    let lock = create_run_storage(&id).unwrap();
    let node = Ipc::new("plant", &id, crate::config::launch::Mode::Realtime).unwrap();
    let _publisher = node.publisher::<u64>(Topic::State, crate::runtime::transport::ipc::Wake::Futex).unwrap();
    let mut snapshot = Snapshot::<u64>::open(&id, "plant").unwrap();
    snapshot.write(&7);
    let folder = std::fs::symlink_metadata(run_folder(&id)).unwrap();
    assert_eq!(folder.permissions().mode() & 0o777, 0o700);
    let files = files_of_run(&id);
    assert!(files.iter().any(|f| f.ends_with(".global_mgmt")), "{files:?}");
    assert!(files.iter().any(|f| f.ends_with("plant.snapshot")), "{files:?}");
    // What lies in the shared folder is the owner's alone; what lies in the run's folder
    // only the owner can reach.
    for file in files.iter().filter(|f| std::path::Path::new(f).parent() == Some(std::path::Path::new(SHM_DIR))) {
        let mode = std::fs::symlink_metadata(file).unwrap().permissions().mode();
        assert_eq!(mode & 0o077, 0, "{file} is open to others: {:o}", mode & 0o777);
    }
    assert!(!std::path::Path::new("/tmp/iceoryx2").join(file_prefix(&id)).exists());
    drop(snapshot);
    drop(_publisher);
    drop(node);
    let cleanup = clean_up_run(&id).unwrap();
    assert!(cleanup.leftover.is_empty(), "{:?}", cleanup.leftover);
    drop(lock);
}

#[test]
fn a_planted_symlink_is_refused_and_its_target_untouched() {
    let id = unique_id("symlink");
    let target = std::env::temp_dir().join(format!("looplab-victim-{id}"));
    std::fs::create_dir_all(&target).unwrap();
    let victim = target.join("plant.snapshot");
    std::fs::write(&victim, b"precious").unwrap();
    std::os::unix::fs::symlink(&target, run_folder(&id)).unwrap();
    give_away(&run_folder(&id));

    let e = create_run_storage(&id).unwrap_err().to_string();
    assert!(e.contains("exists already"), "{e}");
    let e = Snapshot::<u64>::open(&id, "plant").err().expect("refused").to_string();
    assert!(e.contains("symbolic link"), "{e}");
    let e = Ipc::new("plant", &id, crate::config::launch::Mode::Realtime).err().expect("refused").to_string();
    assert!(e.contains("symbolic link"), "{e}");
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
    assert_eq!(std::fs::read_dir(&target).unwrap().count(), 1, "nothing was created through the link");

    std::fs::remove_file(run_folder(&id)).unwrap();
    std::fs::remove_dir_all(&target).unwrap();
}

#[test]
fn a_folder_precreated_by_another_user_with_a_forged_snapshot_is_refused() {
    let id = unique_id("forged");
    let folder = run_folder(&id);
    std::fs::DirBuilder::new().create(&folder).unwrap();
    std::fs::set_permissions(&folder, std::fs::Permissions::from_mode(0o700)).unwrap();
    std::fs::write(folder.join("plant.snapshot"), [0xffu8; 64]).unwrap();
    let foreign = give_away(&folder.join("plant.snapshot")) && give_away(&folder);
    let expected = if foreign { "belongs to user 65534" } else { "exists already" };

    let e = create_run_storage(&id).unwrap_err().to_string();
    assert!(e.contains("exists already"), "{e}");
    if foreign {
        let e = Snapshot::<u64>::open(&id, "plant").err().expect("refused").to_string();
        assert!(e.contains(expected), "{e}");
        assert_eq!(std::fs::symlink_metadata(&folder).unwrap().uid(), 65534, "left as it was");
    }
    // A folder of ours that others may enter is refused too.
    std::fs::remove_dir_all(&folder).unwrap();
    std::fs::DirBuilder::new().create(&folder).unwrap();
    std::fs::set_permissions(&folder, std::fs::Permissions::from_mode(0o755)).unwrap();
    let e = check_private(&folder).unwrap_err().to_string();
    assert!(e.contains("can be used by other users (mode 755)"), "{e}");
    std::fs::remove_dir_all(&folder).unwrap();
}
