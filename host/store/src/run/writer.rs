//! Recording a run: frames appended to its log as they arrive, filed once, the metadata kept current.

use super::*;

/// Records a run: appends frames to its log as they arrive.
pub struct RunWriter {
    pub(super) dir: PathBuf,
    pub(super) meta: RunMeta,
    pub(super) log: LogWriter,
    pub(super) data: Assembled,
    pub(super) last_sync: Instant,
}

impl RunWriter {
    /// Creates a new run folder under `store` (created if needed) and writes its metadata.
    pub fn create(store: &Path, mut meta: RunMeta) -> Result<RunWriter> {
        std::fs::create_dir_all(store).map_err(|e| {
            StoreError::io(
                format!(
                    "cannot create the store {} (use --store DIR)",
                    store.display()
                ),
                e,
            )
        })?;
        let base = meta.folder_name();
        let mut n = 1;
        let dir = loop {
            let name = if n == 1 {
                base.clone()
            } else {
                format!("{base}-{n}")
            };
            let dir = store.join(&name);
            match std::fs::create_dir(&dir) {
                Ok(()) => {
                    meta.id = name;
                    break dir;
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && n < 1000 => n += 1,
                Err(e) => {
                    return Err(StoreError::io(
                        format!("cannot create run folder {}", dir.display()),
                        e,
                    ))
                }
            }
        };
        meta.status = RunStatus::Recording;
        write_toml_atomic(&dir.join(META_FILE), &meta)?;
        let log = LogWriter::create(
            &dir.join(LOG_FILE),
            meta.device.as_ref().map(|d| d.protocol),
        )?;
        // The run as assembled while it is written knows the protocol the log states, as a
        // reader of the log will: what the run must hold (the analog chain of a v3 rig) is judged
        // the same way while it is pulled and when it is read back.
        let data = Assembled::from_records(&[], log.header().protocol);
        Ok(RunWriter {
            dir,
            meta,
            log,
            data,
            last_sync: Instant::now(),
        })
    }

    /// Reopens a run to add frames (after a lost link or a killed recorder), cutting a torn tail.
    /// With `salvage`, a corrupt log is cut after its intact prefix. Returns the writer and what
    /// was cut, if anything.
    pub fn resume(dir: &Path, salvage: bool) -> Result<(RunWriter, Option<Recovery>)> {
        let meta: RunMeta = read_toml(&dir.join(META_FILE))?;
        let (log, contents) = LogWriter::reopen(
            &dir.join(LOG_FILE),
            salvage,
            meta.device.as_ref().map(|d| d.protocol),
        )?;
        let data = Assembled::from_records(&contents.records, contents.header.protocol);
        Ok((
            RunWriter {
                dir: dir.to_owned(),
                meta,
                log,
                data,
                last_sync: Instant::now(),
            },
            contents.recovery,
        ))
    }

    /// The run's folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Its metadata.
    pub fn meta(&self) -> &RunMeta {
        &self.meta
    }

    /// Its metadata, to change before it is saved.
    pub fn meta_mut(&mut self) -> &mut RunMeta {
        &mut self.meta
    }

    /// Logs one raw wire frame (as received) and files the message it holds. Frames that do not
    /// decode are refused (the link layer asks again for them).
    pub fn append_frame(&mut self, raw: &[u8]) -> Result<()> {
        let f = self.decode(raw)?;
        self.log_frame(raw, f)
    }

    /// Files one raw wire frame (as received) into the run: logs it if the run does not hold it
    /// yet; a frame the run already holds byte for byte is not logged twice; a frame whose place
    /// the run holds with other bytes is of another run, and is not logged either (the caller
    /// decides). Frames that do not decode are refused.
    pub fn file_frame(&mut self, raw: &[u8]) -> Result<Filed> {
        let f = self.decode(raw)?;
        let Some(slot) = Slot::of(&f.msg) else {
            return Ok(Filed::Other);
        };
        if let Some((_, held)) = self.data.raw.get(&slot) {
            return Ok(if held[..] == *raw {
                Filed::Same
            } else {
                Filed::Differs(slot.name())
            });
        }
        self.log_frame(raw, f)?;
        Ok(Filed::New)
    }

    pub(super) fn decode(&self, raw: &[u8]) -> Result<tribo_wire::Frame<DeviceMsg>> {
        tribo_wire::v1::decode_as(self.log.header().protocol, raw)
            .map_err(|e| StoreError::caused(ErrorKind::Invalid, "refusing to log a bad frame", e))
    }

    pub(super) fn log_frame(&mut self, raw: &[u8], f: tribo_wire::Frame<DeviceMsg>) -> Result<()> {
        let msg = f.msg;
        let is_header = matches!(msg, DeviceMsg::RunStarted(_));
        let is_end = matches!(msg, DeviceMsg::RunEnded(_) | DeviceMsg::Result(_));
        if let DeviceMsg::RunStarted(h) = &msg {
            self.meta.device_run_id = Some(h.run_id);
            if h.temp_c.is_finite() {
                self.meta.temp_c = Some(clean(h.temp_c));
            }
        }
        if is_header {
            // The rig's run id is how `tribo pull` finds this folder again, even if this process
            // is killed before `finish`: written before the header goes into the log, so that no
            // moment leaves a logged header in a folder `tribo pull` cannot find (a folder killed
            // in between holds the run id and no header; the pull asks the rig for the header).
            write_toml_atomic(&self.dir.join(META_FILE), &self.meta)?;
        }
        self.log.append(raw)?;
        self.data.add(f.seq, raw, msg);
        if is_header || is_end || self.last_sync.elapsed() >= Duration::from_secs(1) {
            self.log.sync()?;
            self.last_sync = Instant::now();
        }
        Ok(())
    }

    /// Block `i`, if logged.
    pub fn block(&self, i: u32) -> Option<&SampleBlock> {
        self.data.blocks.get(&i)
    }

    /// Whether this frame is a run event (gap, ECR range change) already logged.
    pub fn has_event(&self, msg: &DeviceMsg) -> bool {
        self.data.has_event(msg)
    }

    /// Acquisition gaps logged so far.
    pub fn gaps(&self) -> impl Iterator<Item = &Gap> {
        self.data.gaps.values()
    }

    /// Whether block `i` is already logged.
    pub fn has_block(&self, i: u32) -> bool {
        self.data.blocks.contains_key(&i)
    }

    /// Sample blocks received so far.
    pub fn blocks(&self) -> usize {
        self.data.blocks.len()
    }

    /// The run's header frame, if received.
    pub fn header(&self) -> Option<&RunHeader> {
        self.data.header.as_ref()
    }

    /// The run's end frame, if received.
    pub fn end(&self) -> Option<&RunEnd> {
        self.data.end.as_ref()
    }

    /// The on-board result, if received.
    pub fn onboard(&self) -> Option<&OnboardResult> {
        self.data.result.as_ref()
    }

    /// The blocks not received, as far as the run is known.
    pub fn missing_blocks(&self) -> Vec<u32> {
        self.data.missing()
    }

    /// First block a resumed `Pull` should ask for.
    pub fn resume_from(&self) -> u32 {
        self.data.resume_from()
    }

    /// Header, every block and event, result and end present ([`Completeness::is_complete`]).
    pub fn is_complete(&self) -> bool {
        self.data.completeness().is_complete()
    }

    /// How much of the run is held.
    pub fn completeness(&self) -> Completeness {
        self.data.completeness()
    }

    /// Blocks held that this tribo cannot unpack ([`Completeness::undecodable`]).
    pub fn undecodable_blocks(&self) -> &[u32] {
        &self.data.undecodable_blocks
    }

    /// Blocks before which run events look missing ([`Completeness::event_holes`]).
    pub fn event_holes(&self) -> Vec<u32> {
        self.data.event_holes()
    }

    /// The highest block held, if any.
    pub fn last_block(&self) -> Option<u32> {
        self.data.blocks.keys().next_back().copied()
    }

    /// Whether the on-board result is held.
    pub fn has_result(&self) -> bool {
        self.data.result.is_some()
    }

    /// The run frames held, in the rig's order ([`Run::frames`]).
    pub fn frames(&self) -> Vec<&[u8]> {
        self.data.frames()
    }

    /// How many run frames are held.
    pub fn frames_held(&self) -> usize {
        self.data.raw.len()
    }

    /// Syncs the log and writes the metadata with its final status; the status is derived from
    /// what was received unless `aborted`. Returns the run read back.
    pub fn finish(mut self, aborted: bool) -> Result<Run> {
        self.log.sync()?;
        let recorded = if aborted {
            RunStatus::Aborted
        } else {
            RunStatus::Incomplete
        };
        self.meta.status = derive_status(recorded, &self.data);
        write_toml_atomic(&self.dir.join(META_FILE), &self.meta)?;
        Run::open(&self.dir)
    }

    /// Writes the metadata as it is now (e.g. after the link was lost), leaving the log open.
    pub fn checkpoint(&mut self, status: RunStatus) -> Result<()> {
        self.log.sync()?;
        self.meta.status = status;
        write_toml_atomic(&self.dir.join(META_FILE), &self.meta)
    }
}
